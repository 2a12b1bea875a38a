"""Verbs made of sub-verbs (`buddybot.cli.subverbs`), on the real `buddybot` parser in-process:
operands checked by argparse, the common and shared options on either side of the
sub-verb, one usage line for wrong operands, and the sub-verb's `main` chosen."""

from __future__ import annotations

import argparse

import pytest

from buddybot import cli
from buddybot.cli import bag, node, param, subverbs


def parse(*argv: str) -> argparse.Namespace:
    return cli.build_parser().parse_args(list(argv))


def test_the_chosen_sub_verb_runs() -> None:
    args = parse("param", "set", "radar-presence", "range_m", "1.5")
    assert (args.node, args.field, args.value) == ("radar-presence", "range_m", "1.5")
    assert args.subverb_main is dict((s.name, s.main) for s in param.SUBVERBS)["set"]
    assert parse("bag", "info", "f.mcap").subverb_main is bag.info
    assert parse("node", "info", "camera").subverb_main is node.info


def test_common_and_shared_options_go_before_or_after_the_sub_verb() -> None:
    after = parse("param", "list", "camera", "--robot", "r2", "--timeout", "1.5")
    before = parse("param", "--robot", "r2", "--timeout", "1.5", "list", "camera")
    for args in (after, before):
        assert args.robot == "r2" and args.timeout == 1.5
    plain = parse("param", "list", "camera")
    assert plain.robot is None and plain.timeout == 5.0 and plain.log_level == "INFO"
    assert parse("bag", "--robot", "lab", "play", "f.mcap").robot == "lab"


@pytest.mark.parametrize(("argv", "line"), [
    (["param", "set", "n", "f"], "buddybot param: usage: buddybot param set NODE FIELD VALUE"),
    (["param", "get", "n", "a", "b"], "buddybot param: usage: buddybot param get NODE FIELD"),
    (["param", "list", "n", "x"], "buddybot param: usage: buddybot param list NODE"),
    (["param", "load", "n"], "buddybot param: usage: buddybot param load NODE FILE"),
])
def test_wrong_operands_get_one_usage_line(argv: list[str], line: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        cli.main(argv)
    assert exited.value.code == 2
    assert capsys.readouterr().err == line + "\n"


@pytest.mark.parametrize(("argv", "needle"), [
    (["param", "bogus", "n"], "argument op: invalid choice: 'bogus'"),
    (["node", "bogus", "x"], "argument action: invalid choice: 'bogus'"),
    (["bag", "play"], "buddybot bag play: error: the following arguments are required: FILE"),
    (["param", "list", "n", "--timeout", "x"], "argument --timeout: invalid float value: 'x'"),
    (["param", "set", "n", "f", "v", "--colour"], "unrecognized arguments: --colour"),
])
def test_other_usage_errors_are_argparse_s(argv: list[str], needle: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        cli.main(argv)
    assert exited.value.code == 2
    assert needle in capsys.readouterr().err


def test_each_sub_verb_has_its_own_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["param", "dump", "--help"])
    out = capsys.readouterr().out
    assert out.startswith("usage: buddybot param dump") and "--output FILE" in out
    assert "--connect" in out


@pytest.mark.parametrize("argv", [
    ["param", "--json", "list", "n"], ["param", "set", "n", "f", "v", "--json"],
    ["param", "get", "--json", "n", "f"], ["param", "dump", "n", "-o", "x.toml"],
    ["node", "--json", "info", "n"], ["node", "info", "n", "--json", "--timeout", "1"],
])
def test_options_shared_by_a_verb_parse_before_or_after_the_sub_verb(argv: list[str]) -> None:
    """Command lines that worked before sub-verbs became sub-parsers still parse."""
    parsed = cli.build_parser().parse_args(argv)
    assert parsed.subverb_main is not None


def test_a_verb_made_of_sub_verbs_runs_the_chosen_one() -> None:
    ran: list[str] = []
    parser = argparse.ArgumentParser(prog="buddybot demo")
    subverbs.add_subverbs(parser, [
        subverbs.SubVerb("a", "first", lambda p: p.add_argument("x"),
                         lambda ctx: ran.append(f"a {ctx.args.x}") or 0),
        subverbs.SubVerb("b", "second", lambda p: None, lambda ctx: ran.append("b") or 3),
    ])
    args = parser.parse_args(["b"])
    assert subverbs.run(argparse.Namespace(args=args)) == 3  # type: ignore[arg-type]
    assert subverbs.run(argparse.Namespace(args=parser.parse_args(["a", "1"]))) == 0  # type: ignore[arg-type]
    assert ran == ["b", "a 1"]
