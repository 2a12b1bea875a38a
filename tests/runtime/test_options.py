"""The options several verbs share (`buddybot.runtime.options`): one spelling, one way of
saying the default, and the same parsing everywhere, `buddybot radar` included."""

from __future__ import annotations

import argparse

import pytest

from buddybot import cli
from buddybot.radar import tool
from buddybot.runtime.session import CONNECT_TIMEOUT_S


def help_of(*argv: str, capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit):
        cli.main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())  # argparse's line wrapping undone


@pytest.mark.parametrize("argv", [("call", "k"), ("echo",), ("hz",), ("pub",), ("nodes",),
                                  ("topics",), ("doctor",), ("param", "get"), ("node", "info"),
                                  ("bag", "record"), ("bag", "play")])
def test_every_timeout_is_seconds_with_its_default_said(
        argv: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    text = help_of(*argv, capsys=capsys)
    assert "--timeout S " in text
    said = text.split("--timeout S ")[1].split(" --")[0]  # up to the next option
    assert "(default " in said or "(default: none" in said


def test_a_probe_without_timeout_names_the_connection_limit(
        capsys: pytest.CaptureFixture[str]) -> None:
    text = help_of("echo", capsys=capsys)
    assert f"the router must answer within {CONNECT_TIMEOUT_S:g} s" in text
    assert "connecting included" in text
    assert "connecting included" not in help_of("param", "get", capsys=capsys)


def test_timeouts_parse_as_each_verb_requires() -> None:
    parser = cli.build_parser()
    assert parser.parse_args(["hz", "k"]).timeout is None
    assert parser.parse_args(["topics"]).timeout == 3.0
    assert parser.parse_args(["doctor", "--timeout", "2.5"]).timeout == 2.5
    with pytest.raises(SystemExit):
        parser.parse_args(["doctor", "--timeout", "0"])  # doctor's own check: (0, 60]


@pytest.mark.parametrize("argv", [("keys",), ("config",), ("nodes",), ("hz", "k"), ("topics",),
                                  ("doctor",), ("param", "list", "n"), ("node", "info", "n"),
                                  ("bag", "info", "f")])
def test_json_is_a_flag_wherever_it_is(argv: tuple[str, ...]) -> None:
    parser = cli.build_parser()
    assert parser.parse_args([*argv, "--json"]).json is True
    assert parser.parse_args(list(argv)).json is False


def test_a_publication_key_takes_no_wildcard_in_its_help(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert "wildcards allowed" in help_of("echo", capsys=capsys)
    assert "wildcards allowed" not in help_of("pub", capsys=capsys)


def test_the_radar_verb_keeps_its_own_spelling_of_the_shared_options(
        capsys: pytest.CaptureFixture[str]) -> None:
    text = help_of("radar", "info", capsys=capsys)
    assert "--timeout TIMEOUT seconds to wait for each ACK (default 1.0)" in text
    assert "--json print results as JSON" in text
    parser = argparse.ArgumentParser()
    tool.add_arguments(parser)
    assert parser.parse_args(["info", "--json"]).json is True
    assert parser.parse_args(["info"]).timeout == 1.0
