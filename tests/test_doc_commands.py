"""Every command the README and docs/*.md show is checked against the code
(and the `buddybot` and repository commands of the deployment guide,
deploy/README.md, whose host tools are not ours to check).

Commands are taken from fenced code blocks (```sh, ```bash, ```shell: every
line; ```console: the `$ ` lines; any other block: lines starting with
`$ `, `buddybot `, `.venv/bin/` or `scripts/`) and from inline code spans
that start with `buddybot `. Then:

* every `buddybot ...` command is parsed by the real parsers: the verb
  parser (`buddybot.cli.build_parser`), and for `run SERVICE` and the tool
  verbs (`radar`) the service's or tool's own parser, built as the CLI
  builds it, so a wrong verb, action or option fails here. Synopsis
  notation is read as a reader would: `on|off` -> `on`, `[--wait]` ->
  `--wait`. An inline span without options (`buddybot call KEY [JSON]`,
  a verb named in prose) only needs its verb, service or action to exist;
* the quick commands without side effects (`--help`, `--version`, `keys`,
  `config`, `schemas --check`) are also run as processes and must exit 0
  (marked integration: they start processes). Long-running commands (`up`,
  `run`, `router`, the probes) and the ones needing hardware (`radar`) are
  parse-checked only;
* the tutorial of docs/apps.md is run as a reader would, in order, against
  `up --sim` (`test_the_apps_tutorial_runs`, integration): `app new hello`,
  `app run hello.py` as generated and as edited on the page, `[apps]`;
* so is docs/tutorial.md (`test_the_tutorial_runs`, integration): its
  `robot.toml`, `config` of it, `scripts/run.sh --config robot.toml` (as the
  `up` it runs), `echo` of the sound status until the spoken greeting
  succeeds, `app new` and `app run`; only `apt-get` is not run;
* other commands: `scripts/...` and `benchmarks/...` run directly must
  exist and be executable; files given to `.venv/bin/python` and paths
  given to pytest must exist; `make TARGET` must be a Makefile target;
  other programs must be in `EXTERNAL` (tools of the host, not ours).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from buddybot import cli
from buddybot.runtime import registry
from buddybot.runtime.service import add_common_arguments
from buddybot.tools import testing

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
        *sorted((ROOT / "docs" / "howto").glob("*.md"))]
GUIDES = [ROOT / "deploy" / "README.md"]
"""Checked for `buddybot` and repository commands only: they show many host tools."""
FENCE = re.compile(r"^\s*```(\S*)\s*$")
SHELL_BLOCKS = {"sh", "bash", "shell"}
LINE_STARTS = ("$ ", "buddybot ", ".venv/bin/", "scripts/")
INLINE = re.compile(r"`((?:\.venv/bin/)?buddybot [^`]+)`")
PLACEHOLDERS = {"VERB", "SERVICE", "ACTION"}
"""Synopsis words standing for a choice: a span containing one is not parsed."""
EXTERNAL = {"zenoh", "sudo", "install", "systemctl", "journalctl", "openssl", "pip",
            "apt-get", "git", "chromium", "espeak-ng", "sox", "ssh", "esphome",
            "cd", "cp", "ls", "udevadm", "v4l2-ctl", "aplay", "speaker-test", "useradd",
            "usermod"}
"""Programs of the host (not this repository) that docs may show."""
QUICK = {"keys", "config", "schemas"}
"""Verbs that only read or check: run as processes (with `--help` and `--version`)."""


@dataclass(frozen=True)
class Command:
    where: str
    text: str
    inline: bool = False
    strict: bool = True
    """False: a program that is not ours is not checked (a guide's host tools)."""

    def __str__(self) -> str:
        return f"{self.where}: {self.text}"


def _strip_comment(line: str) -> str:
    """`cmd  # comment` -> `cmd`; a `#` inside quotes or a word stays."""
    quote = None
    for i, char in enumerate(line):
        if char in "'\"" and quote in (None, char):
            quote = None if quote else char
        elif char == "#" and quote is None and (i == 0 or line[i - 1].isspace()):
            return line[:i].strip()
    return line.strip()


def commands_in(path: Path, strict: bool = True) -> list[Command]:
    found: list[Command] = []
    name = path.relative_to(ROOT).as_posix()
    lang: str | None = None
    pending = ""
    for number, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        fence = FENCE.match(raw)
        if fence:
            lang = None if lang is not None else fence.group(1)
            pending = ""
            continue
        if lang is None:
            found += [Command(f"{name}:{number}", m.group(1).strip(), inline=True,
                              strict=strict) for m in INLINE.finditer(raw)]
            continue
        line = (pending + " " + raw.strip()).strip() if pending else raw.strip()
        pending = ""
        if line.endswith("\\"):
            pending = line[:-1].strip()
            continue
        keep = (line.startswith("$ ") if lang == "console"
                else lang in SHELL_BLOCKS or line.startswith(LINE_STARTS))
        if not keep:
            continue
        line = line.removeprefix("$ ")
        line = _strip_comment(line)
        if line:
            found.append(Command(f"{name}:{number}", line, strict=strict))
    return found


ALL = [*(c for path in DOCS for c in commands_in(path)),
       *(c for path in GUIDES for c in commands_in(path, strict=False))]


def words(text: str) -> list[str]:
    """Shell words, with synopsis notation resolved (`a|b` -> a, `[x]` -> x)."""
    out = []
    for word in shlex.split(text):
        if not word.startswith(("{", "'", '"')) and "|" in word and "/" not in word:
            word = word.split("|")[0]
        word = word.strip("[]") if not word.startswith("{") else word
        if word:
            out.append(word)
    return out


def buddybot_argv(argv: list[str]) -> list[str] | None:
    """The arguments after the program when `argv` runs buddybot, else None."""
    if argv and (argv[0] == "buddybot" or argv[0].endswith("/bin/buddybot")):
        return argv[1:]
    if len(argv) >= 3 and argv[0].endswith("python") and argv[1:3] == ["-m", "buddybot"]:
        return argv[3:]
    return None


class ParseFailure(Exception):
    pass


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            return parser.parse_args(argv)
    except SystemExit as exit_:
        if exit_.code in (0, None):  # --help / --version
            return argparse.Namespace()
        raise ParseFailure(err.getvalue().strip().splitlines()[-1]) from None


@functools.cache
def _cli_parser() -> argparse.ArgumentParser:
    """The CLI's parser, built once for every command checked (parsing leaves it as is)."""
    return cli.build_parser()


@functools.cache
def _extension_parser(entry: registry.Entry, prog: str) -> argparse.ArgumentParser:
    """The parser `buddybot.cli._extension` builds for a service or tool."""
    parser = argparse.ArgumentParser(prog=prog, description=entry.help)
    add_common_arguments(parser)
    entry.load().add_arguments(parser)
    return parser


def check_buddybot(argv: list[str], *, full: bool) -> None:
    """Parse `buddybot <argv>` as the CLI would; `full=False`: names only."""
    tool = next((t for t in registry.TOOLS if argv and argv[0] == t.name), None)
    if tool is not None:
        parser = _extension_parser(tool, f"buddybot {tool.name}")
        if full:
            _parse(parser, argv[1:])
        elif len(argv) > 1:
            actions = next(a for a in parser._actions if a.dest == "action")
            assert argv[1] in actions.choices, f"no action {argv[1]!r}"  # type: ignore[operator]
        return
    if not full:
        verbs = next(a for a in _cli_parser()._actions if a.dest == "verb").choices
        assert argv and argv[0] in verbs, f"no verb {argv[:1]}"  # type: ignore[operator]
        if argv[0] == "run" and len(argv) > 1:
            assert registry.service(argv[1]) is not None, f"no service {argv[1]!r}"
        return
    args = _parse(_cli_parser(), argv)
    if getattr(args, "verb", None) == "run":
        entry = registry.service(args.service)
        assert entry is not None
        _parse(_extension_parser(entry, f"buddybot run {entry.name}"), args.service_args)


def check_other(argv: list[str], strict: bool = True) -> None:
    program = argv[0]
    if program.startswith(("scripts/", "benchmarks/")):
        path = ROOT / program
        assert path.is_file(), f"{program} does not exist"
        assert os.access(path, os.X_OK), f"{program} is not executable (run it with python?)"
    elif program.endswith("/python") or program in ("python", "python3"):
        if argv[1:2] != ["-m"]:
            script = next((a for a in argv[1:] if not a.startswith("-")), None)
            assert script and (ROOT / script).is_file(), f"{script} does not exist"
    elif program.endswith("/pytest") or program == "pytest":
        for arg in argv[1:]:
            if not arg.startswith("-") and ("/" in arg or arg.endswith(".py")):
                assert (ROOT / arg.split("::")[0]).exists(), f"{arg} does not exist"
    elif program == "make":
        targets = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M)
        for target in argv[1:]:
            assert target in targets, f"make {target}: no such target"
    elif strict:
        assert program in EXTERNAL, (
            f"{program}: not a command of this repository; add it to EXTERNAL if it is "
            "a host tool the docs may show")


def test_the_docs_show_commands() -> None:
    """The extraction finds what it must (else every check below passes vacuously)."""
    texts = [c.text for c in ALL]
    assert any(t.startswith("scripts/run.sh") for t in texts)
    assert any(t.startswith("buddybot radar info") for t in texts)
    assert sum(1 for t in texts if t.startswith("buddybot ")) > 20


def test_the_parse_check_refuses_a_wrong_command() -> None:
    for wrong in (["radar", "--port", "/dev/ttyUSB0", "info"], ["echoo", "radar/presence"],
                  ["run", "camera", "--no-such-option"], ["hz", "camera/front/image", "--bad"]):
        with pytest.raises(ParseFailure):
            check_buddybot(wrong, full=True)
    check_buddybot(["radar", "info", "--port", "/dev/ttyUSB0"], full=True)


@pytest.mark.parametrize("command", ALL, ids=str)
def test_command_is_valid(command: Command) -> None:
    argv = words(command.text)
    bb = buddybot_argv(argv)
    if bb is None:
        if command.inline:
            return
        check_other(argv, command.strict)
        return
    if command.inline and (PLACEHOLDERS & set(bb) or "..." in bb):
        return  # a synopsis (`buddybot run SERVICE --help`), not a command
    full = not command.inline or any(w.startswith("-") for w in bb)
    problem = ""
    try:
        check_buddybot(bb, full=full)
    except ParseFailure as error:
        problem = f"the CLI refuses it: {error}"
    except AssertionError as error:
        problem = str(error).splitlines()[0]
    if problem:
        pytest.fail(f"{command}\n  {problem}", pytrace=False)


def _quick(argv: list[str]) -> bool:
    if "--help" in argv or "-h" in argv or argv == ["--version"]:
        return True
    if not argv or argv[0] not in QUICK:
        return False
    if argv[0] == "schemas":
        return "--check" in argv  # without it, it rewrites schemas/
    if "--config" in argv:
        i = argv.index("--config")
        return i + 1 < len(argv) and (ROOT / argv[i + 1]).is_file()
    return True


QUICK_COMMANDS = sorted({
    " ".join(bb) for c in ALL
    if (bb := buddybot_argv(words(c.text))) is not None and _quick(bb)
    and not PLACEHOLDERS & set(bb)} | {"--help", "--version"})


@pytest.mark.integration
@pytest.mark.parametrize("argv", QUICK_COMMANDS)
def test_quick_command_runs(argv: str) -> None:
    env = {k: v for k, v in os.environ.items() if k != "BUDDYBOT_CONFIG"}
    result = subprocess.run([sys.executable, "-m", "buddybot", *shlex.split(argv)], cwd=ROOT,
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"buddybot {argv}: exit {result.returncode}\n{result.stderr}"
    if not argv.startswith("schemas"):  # a successful check is silent
        assert result.stdout.strip(), f"buddybot {argv} printed nothing"


# --- docs/apps.md: the tutorial, run as a reader would --------------------------------

APPS_DOC = ROOT / "docs" / "apps.md"


def _blocks(path: Path, lang: str) -> list[str]:
    """The text of each fenced block of `lang` in `path`."""
    out, current = [], None
    for line in path.read_text(encoding="utf-8").splitlines():
        fence = FENCE.match(line)
        if fence and current is None and fence.group(1) == lang:
            current = []
        elif fence and current is not None:
            out.append("\n".join(current) + "\n")
            current = None
        elif current is not None:
            current.append(line)
    return out


def _tutorial_command(start: str) -> list[str]:
    found = [c.text for c in commands_in(APPS_DOC) if not c.inline and c.text.startswith(start)]
    assert found, f"docs/apps.md shows no `{start}...` command"
    argv = buddybot_argv(words(found[0]))
    assert argv is not None
    return argv


@pytest.mark.integration
def test_the_apps_tutorial_runs(tmp_path: Path) -> None:
    """`up --sim`, `app new hello`, `app run hello.py` (as generated, then as edited in
    the page: it greets the simulated visitor), then `[apps]` read by `app list`."""
    up_words = _tutorial_command("buddybot up --sim")
    audio = tmp_path / "audio.toml"
    audio.write_text('[audio_player]\nbackend = "null"\n')
    endpoint = f"tcp/127.0.0.1:{testing.free_port()}"
    ports = [str(testing.free_port()) for _ in range(2)]
    up = testing.Process(testing.buddybot_argv(
        *up_words, "--no-browser", "--listen", endpoint, "--config", str(audio),
        "--eye-port", ports[0], "--dashboard-port", ports[1], "--status-period", "1"),
        "up", tmp_path / "logs")
    env = {k: v for k, v in os.environ.items() if k != "BUDDYBOT_CONFIG"}

    def run_app(name: str) -> testing.Process:
        """The page's `buddybot app run hello.py`, run in the reader's folder."""
        argv = [str(tmp_path / a) if a == "hello.py" else a
                for a in _tutorial_command("buddybot app run hello.py")]
        return testing.Process(testing.buddybot_argv(*argv, "--connect", endpoint), name,
                               tmp_path / "logs")

    try:
        up.wait_for_output(" | face ", 120)
        new = subprocess.run(testing.buddybot_argv(*_tutorial_command("buddybot app new hello")),
                             cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
        assert new.returncode == 0 and (tmp_path / "hello.py").is_file(), new.stderr
        generated = run_app("hello-generated")
        generated.wait_for_output("hello: watching robot buddy; present now:", 60)
        assert generated.stop() == 0

        edited = _blocks(APPS_DOC, "python")
        assert len(edited) == 1
        (tmp_path / "hello.py").write_text(edited[0])
        greeting = run_app("hello-edited")
        greeting.wait_for_output("hello: greeted person ", 90)
        assert greeting.stop() == 0

        table = next(b for b in _blocks(APPS_DOC, "toml") if "[apps]" in b)
        (tmp_path / "robot.toml").write_text(table)
        listed = subprocess.run(
            testing.buddybot_argv(*_tutorial_command("buddybot app list"), "--connect", endpoint),
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
        assert listed.returncode == 0, listed.stderr
        assert "[apps] run (robot.toml):\n  hello.py" in listed.stdout, listed.stdout
    finally:
        up.stop(30)


# --- docs/tutorial.md: run as a reader would, in order -----------------------------------

TUTORIAL = ROOT / "docs" / "tutorial.md"
NOT_RUN = {"sudo", "apt-get"}
"""Tutorial commands that change the host (installing espeak-ng): validated only."""


@pytest.mark.integration
@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="the tutorial's greeting is spoken: needs espeak-ng "
                           "(scripts/test-packages.sh installs it)")
def test_the_tutorial_runs(tmp_path: Path) -> None:
    """Every command of docs/tutorial.md, in its order, in a reader's folder: the
    page's `robot.toml`, `config` of it, `scripts/run.sh` (the `up` it execs) with
    and without it, `echo` of the sound status until the greeting written on the
    page has been spoken (rendered by espeak-ng into this test's temporary folder),
    `app new hello` and `app run hello.py`. A command the test does not know fails it."""
    (toml,) = [b for b in _blocks(TUTORIAL, "toml") if "[audio.sounds]" in b]
    assert "say:" in toml
    # A test host must stay silent: the null device plays in real time like a card.
    (tmp_path / "robot.toml").write_text(toml + '\n[audio_player]\nbackend = "null"\n')
    env = {k: v for k, v in os.environ.items() if k != "BUDDYBOT_CONFIG"}
    tts = tmp_path / "tts"
    tts.mkdir()
    endpoint = f"tcp/127.0.0.1:{testing.free_port()}"
    ports = [str(testing.free_port()) for _ in range(2)]
    logs = tmp_path / "logs"

    def local(argv: list[str]) -> list[str]:
        """The page's file names, in the reader's folder."""
        return [str(tmp_path / a) if a in ("robot.toml", "hello.py") else a for a in argv]

    up: testing.Process | None = None
    ran: list[str] = []
    try:
        for command in (c for c in commands_in(TUTORIAL) if not c.inline):
            argv = words(command.text)
            bb = buddybot_argv(argv)
            if argv[0] in NOT_RUN:
                continue
            ran.append(command.text)
            if argv[0] == "scripts/run.sh":
                if up is not None:
                    up.stop(30)
                up = testing.Process(testing.buddybot_argv(
                    "up", *local(argv[1:]), "--no-browser", "--listen", endpoint,
                    "--eye-port", ports[0], "--dashboard-port", ports[1],
                    "--status-period", "1"), f"up-{len(ran)}", logs, env={"TMPDIR": str(tts)})
                up.wait_for_output(" | face ", 120)
            elif bb is not None and bb[0] == "config":
                done = subprocess.run(testing.buddybot_argv(*local(bb)), cwd=tmp_path, env=env,
                                      capture_output=True, text=True, timeout=60)
                assert done.returncode == 0, done.stderr
                assert "say:Hello" in done.stdout, done.stdout
            elif bb is not None and bb[0] == "echo":
                assert up is not None, "the page echoes before it starts the robot"
                echo = testing.Process(testing.buddybot_argv(*bb, "--connect", endpoint),
                                       "echo", logs)
                try:
                    echo.wait_for_output('"state":"SUCCEEDED"', 120)
                finally:
                    echo.stop()
                assert "play_sound 'greeting'" in up.output()
                assert list((tts / "buddybot-tts").glob("*.wav")), "nothing was spoken"
            elif bb is not None and bb[:2] == ["app", "new"]:
                done = subprocess.run(testing.buddybot_argv(*bb), cwd=tmp_path, env=env,
                                      capture_output=True, text=True, timeout=60)
                assert done.returncode == 0 and (tmp_path / "hello.py").is_file(), done.stderr
            elif bb is not None and bb[:2] == ["app", "run"]:
                app = testing.Process(testing.buddybot_argv(*local(bb), "--connect", endpoint),
                                      "hello", logs)
                try:
                    app.wait_for_output("hello: watching robot buddy; present now:", 60)
                finally:
                    status = app.stop()
                assert status == 0
            else:
                pytest.fail(f"docs/tutorial.md: this test does not run `{command.text}`")
    finally:
        if up is not None:
            up.stop(30)
    assert sum(1 for c in ran if c.startswith("scripts/run.sh")) == 2, ran
    assert any(c.startswith(".venv/bin/buddybot app run") for c in ran), ran
