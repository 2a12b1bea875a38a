"""The `buddybot` command itself (`buddybot.cli`): a `--help` for every verb, `run
SERVICE`, tab completion (argcomplete) and `buddybot --version`.

The unit tests drive argcomplete's own protocol (`_ARGCOMPLETE`, `COMP_LINE`,
`COMP_POINT`) on the real parser in-process; the integration test runs the
installed console script the way the shell hook from `register-python-argcomplete
buddybot` does, completions on fd 8.
"""

from __future__ import annotations

import importlib.metadata
import io
import platform
import subprocess
import sys
from pathlib import Path

import argcomplete
import pytest

from buddybot import __version__, cli
from buddybot.runtime.registry import SERVICES
from tests.cli.process import bb

IFS = "\013"
"""argcomplete's default separator between completions."""


class _Finder(argcomplete.CompletionFinder):
    """argcomplete's finder without its fd 9 debug stream, which would wrap
    (and later close) whatever pytest keeps on that descriptor."""

    def _init_debug_stream(self) -> None:
        pass


def complete(line: str, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """What the shell would offer for `line` with the cursor at its end."""
    monkeypatch.setenv("_ARGCOMPLETE", "1")
    monkeypatch.setenv("COMP_LINE", line)
    monkeypatch.setenv("COMP_POINT", str(len(line)))
    out = io.StringIO()
    exits: list[int] = []
    _Finder()(cli.build_parser(), exit_method=exits.append, output_stream=out)
    assert exits == [0], f"argcomplete gave up on {line!r} (exit {exits})"
    return [c.strip() for c in out.getvalue().split(IFS) if c]


def test_a_verb_completes(monkeypatch: pytest.MonkeyPatch) -> None:
    assert complete("buddybot ec", monkeypatch) == ["echo"]


def test_every_verb_is_offered(monkeypatch: pytest.MonkeyPatch) -> None:
    offered = set(complete("buddybot ", monkeypatch))
    assert set(cli.VERBS) | {"run"} <= offered


def test_a_service_name_completes(monkeypatch: pytest.MonkeyPatch) -> None:
    assert complete("buddybot run came", monkeypatch) == ["camera"]


def test_an_option_completes(monkeypatch: pytest.MonkeyPatch) -> None:
    assert complete("buddybot --vers", monkeypatch) == ["--version"]


def test_the_marker_is_where_global_completion_looks() -> None:
    # `activate-global-python-argcomplete` completes only commands whose module
    # says so in its first 1024 bytes.
    head = Path(cli.__file__).read_bytes()[:1024]
    assert b"PYTHON_ARGCOMPLETE_OK" in head


def test_an_ordinary_run_is_no_completion(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("_ARGCOMPLETE", raising=False)
    cli.complete()  # returns at once: nothing to answer
    assert capsys.readouterr() == ("", "")


def test_version_names_buddybot_python_and_zenoh(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        cli.main(["--version"])
    assert exited.value.code == 0
    zenoh = importlib.metadata.version("eclipse-zenoh")
    assert capsys.readouterr().out.strip() == (
        f"buddybot {__version__} (Python {platform.python_version()}, eclipse-zenoh {zenoh})")


@pytest.mark.integration
def test_the_console_script_answers_the_shell_hook(tmp_path: Path) -> None:
    # What the bash hook does: run the command with the protocol's variables,
    # completions on fd 8, argcomplete's debug output on fd 9.
    script = Path(sys.executable).parent / "buddybot"
    assert script.exists(), f"no console script at {script}: is buddybot installed?"
    env = {"PATH": "/usr/bin:/bin", "_ARGCOMPLETE": "1", "COMP_LINE": "buddybot ec",
           "COMP_POINT": "11", "HOME": str(tmp_path)}
    done = subprocess.run(["bash", "-c", '"$0" 8>&1 9>/dev/null 1>/dev/null 2>&1', str(script)],
                          env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split(IFS) == ["echo "]


VERBS = ["up", "router", "run", "echo", "hz", "pub", "call", "nodes", "keys", "config", "schemas",
         "lease", "radar"]


@pytest.mark.integration
@pytest.mark.parametrize("verb", VERBS)
def test_every_verb_has_help(verb: str) -> None:
    result = bb(verb, "--help")
    assert result.returncode == 0, result.stderr
    assert "usage: buddybot" in result.stdout
    if verb not in ("run", "keys", "schemas"):
        assert "--connect" in result.stdout


@pytest.mark.integration
def test_run_help_lists_every_service() -> None:
    out = bb("run", "--help").stdout
    for entry in SERVICES:
        assert entry.name in out


@pytest.mark.integration
def test_unknown_service_is_refused() -> None:
    result = bb("run", "teleporter")
    assert result.returncode == 2 and "invalid choice" in result.stderr


@pytest.mark.parametrize(("argv", "verbs"), [
    (["router", "--listen", "tcp/127.0.0.1:1"], ("router",)),
    (["run", "controller", "--help"], ("run",)),
    (["--version"], ()),
    (["--vers"], ()),
    (["--help"], None),
    (["-h", "router"], None),
    ([], None),
    (["teleport"], None),
    (["radar", "info"], None),  # a tool: never parsed by this parser
])
def test_the_first_word_names_the_verbs_to_build(argv: list[str],
                                                  verbs: tuple[str, ...] | None) -> None:
    assert cli.named_verbs(argv) == verbs


@pytest.mark.parametrize("argv", [
    ["router", "--listen", "tcp/127.0.0.1:1", "--robot", "r2"],
    ["run", "camera", "--device", "2"],
    ["bag", "info", "f.mcap", "--json"],
    ["param", "set", "eyes", "x", "1"],
    ["doctor", "--quick"],
])
def test_one_verb_parses_as_the_whole_parser_does(argv: list[str]) -> None:
    whole = vars(cli.build_parser().parse_args(argv))
    alone = vars(cli.build_parser(cli.named_verbs(argv)).parse_args(argv))
    assert alone == whole


def modules_after_parsing(argv: list[str]) -> set[str]:
    """The `buddybot.*` modules a fresh interpreter holds after parsing `argv` the
    way `buddybot` does."""
    probe = ("import sys\nfrom buddybot import cli\n"
             f"cli.build_parser(cli.named_verbs({argv!r})).parse_args({argv!r})\n"
             "print(' '.join(m for m in sys.modules if m.startswith('buddybot.')))")
    return set(subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                              check=True, timeout=60).stdout.split())


@pytest.mark.integration
def test_a_verb_loads_no_other_verb() -> None:
    """A router or a service starts without importing every verb (the bag's MCAP
    reader, the sdk, the web login, ...): on a Raspberry Pi that is seconds."""
    loaded = modules_after_parsing(["router", "--listen", "tcp/127.0.0.1:1"])
    assert "buddybot.cli.router" in loaded  # the probe really parsed
    assert {n for n in loaded if n.startswith("buddybot.cli.")} == {"buddybot.cli.router"}
    assert not {n for n in loaded if n.startswith(("buddybot.tools.", "buddybot.sdk"))}
    run = modules_after_parsing(["run", "controller"])
    assert not {n for n in run if n.startswith(("buddybot.cli.", "buddybot.tools."))}
