"""The guide (docs/README.md, docs/tutorial.md, docs/howto/) is kept true here.

Commands in these pages are checked (and the tutorial run) by
tests/test_doc_commands.py; this module checks the rest of what a reader
copies: every page says who it is for in its first line, the index lists
every page, links lead to files and headings that exist, TOML snippets are
configurations the config loader accepts, udev rules are well-formed rule
lines, systemd unit and desktop-entry snippets have their sections, keys and
a `buddybot` command the CLI accepts, the units they name are shipped,
`/etc/buddybot/env` lines name variables of deploy/systemd/env, and
repository paths the pages name exist.
"""

from __future__ import annotations

import configparser
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from buddybot.runtime.config import parse_config
from tests.test_design_doc import _slug
from tests.test_doc_commands import _blocks, buddybot_argv, check_buddybot

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
INDEX = DOCS / "README.md"
TUTORIAL = DOCS / "tutorial.md"
HOWTOS = sorted((DOCS / "howto").glob("*.md"))
GUIDE = [INDEX, TUTORIAL, *HOWTOS]
"""The pages of the guide proper (the area pages are checked by their own tests)."""
SNIPPET_PAGES = [TUTORIAL, *HOWTOS]


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def _ids(paths: list[Path]) -> list[str]:
    return [_rel(p) for p in paths]


def test_the_guide_has_its_pages() -> None:
    names = {p.stem for p in HOWTOS}
    assert {"radars-usb", "usb-camera", "two-screens", "sound-card", "systemd",
            "esp32-radars", "two-hosts-tls", "record-replay", "tune"} <= names
    assert TUTORIAL.is_file() and INDEX.is_file()


@pytest.mark.parametrize("page", [TUTORIAL, *HOWTOS], ids=_ids([TUTORIAL, *HOWTOS]))
def test_every_page_says_who_it_is_for_first(page: Path) -> None:
    lines = [line for line in page.read_text(encoding="utf-8").splitlines() if line.strip()]
    assert lines[0].startswith("# "), f"{_rel(page)}: starts with its title"
    assert lines[1].startswith("For "), (
        f"{_rel(page)}: the line after the title says who the page is for ('For ...')")


def _links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return re.findall(r"\]\(([^)\s]+)\)", text)


def test_the_index_lists_every_page() -> None:
    linked = {(DOCS / link.split("#")[0]).resolve() for link in _links(INDEX)
              if not link.startswith(("http://", "https://", "#"))}
    pages = [p for p in (*DOCS.glob("*.md"), *HOWTOS) if p != INDEX]
    missing = [_rel(p) for p in pages if p.resolve() not in linked]
    assert not missing, f"docs/README.md does not list: {missing}"
    text = INDEX.read_text(encoding="utf-8")
    for heading in ("## Tutorial", "## How-to guides", "## Reference", "## Explanation"):
        assert heading in text, f"docs/README.md: no section {heading!r}"


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {_slug(h) for h in re.findall(r"^#+ (.*)$", text, re.M)}


@pytest.mark.parametrize("page", [ROOT / "README.md", *GUIDE],
                         ids=_ids([ROOT / "README.md", *GUIDE]))
def test_links_lead_to_files_and_headings_that_exist(page: Path) -> None:
    broken = []
    for link in _links(page):
        if link.startswith(("http://", "https://", "mailto:")):
            continue
        target, _, anchor = link.partition("#")
        path = (page.parent / target).resolve() if target else page
        if not path.exists() or (anchor and path.suffix == ".md" and anchor not in _anchors(path)):
            broken.append(link)
    assert not broken, f"{_rel(page)}: broken links {broken}"


SNIPPETS = [(page, block) for page in SNIPPET_PAGES for block in _blocks(page, "toml")]


@pytest.mark.parametrize("page,block", SNIPPETS,
                         ids=[f"{_rel(p)}#{i}" for i, (p, _) in enumerate(SNIPPETS)])
def test_toml_snippets_are_configurations_the_loader_accepts(page: Path, block: str) -> None:
    parse_config(block, _rel(page))  # raises ConfigError naming the key


def test_the_toml_check_refuses_a_wrong_key() -> None:
    from buddybot.runtime.errors import ConfigError

    with pytest.raises(ConfigError):
        parse_config('[camera]\nsorce = "0"\n', "wrong")


UDEV_PAIR = re.compile(
    r'^(?P<key>[A-Z_]+)(?:\{(?P<attr>[^}]+)\})?(?P<op>==|!=|\+=|-=|:=|=)"(?P<value>[^"]*)"$')
UDEV_MATCH = {"ACTION", "DEVPATH", "KERNEL", "KERNELS", "NAME", "SYMLINK", "SUBSYSTEM",
              "SUBSYSTEMS", "DRIVER", "DRIVERS", "ATTR", "ATTRS", "ENV", "TAG", "TAGS"}
UDEV_ASSIGN = {"SYMLINK", "GROUP", "MODE", "OWNER", "TAG", "ENV", "RUN", "NAME"}


def udev_rule_problems(line: str) -> list[str]:
    """What is wrong with one udev rule line (empty: nothing)."""
    problems, matches, assigns = [], 0, 0
    for pair in (p.strip() for p in line.split(",")):
        found = UDEV_PAIR.match(pair)
        if not found:
            problems.append(f"not KEY==\"value\" or KEY=\"value\": {pair!r}")
            continue
        key, op = found["key"], found["op"]
        if op in ("==", "!="):
            matches += 1
            if key not in UDEV_MATCH:
                problems.append(f"{key} cannot be matched")
        else:
            assigns += 1
            if key not in UDEV_ASSIGN:
                problems.append(f"{key} cannot be assigned")
            if key == "SYMLINK" and "/" in found["value"]:
                problems.append("SYMLINK is a name under /dev, without /dev/")
    if not matches or not assigns:
        problems.append("a rule needs a match and an assignment")
    return problems


def test_the_udev_check_refuses_a_broken_rule() -> None:
    assert udev_rule_problems('SUBSYSTEM=="tty", ATTRS{serial}=="1", SYMLINK+="x"') == []
    for bad in ('SUBSYSTEM=="tty", ATTRS{serial}=="1"',          # no assignment
                'SUBSYSTEM=="tty" ATTRS{serial}=="1", SYMLINK+="x"',  # comma missing
                "SUBSYSTEM=='tty', SYMLINK+=\"x\"",                # single quotes
                'SUBSYSTEM=="tty", SYMLINK+="/dev/x"'):
        assert udev_rule_problems(bad), bad


def test_udev_rules_are_well_formed_and_tell_adapters_apart_by_serial() -> None:
    rules = [line for page in SNIPPET_PAGES for block in _blocks(page, "udev")
             for line in block.splitlines() if line.strip() and not line.startswith("#")]
    assert rules, "the radars how-to shows a udev rule"
    for line in rules:
        assert not udev_rule_problems(line), (line, udev_rule_problems(line))
    links = [re.search(r'SYMLINK\+="([^"]+)"', r) for r in rules]
    names = [m.group(1) for m in links if m]
    assert len(names) == len(set(names)), "two rules make the same link"
    assert all("ATTRS{serial}==" in r for r in rules)
    radars = (DOCS / "howto" / "radars-usb.md").read_text(encoding="utf-8")
    for name in names:  # the config snippet uses the links the rules make
        assert f'"/dev/{name}"' in radars


INI_BLOCKS = [(page, block) for page in SNIPPET_PAGES for block in _blocks(page, "ini")]
UNITS = [(p, b) for p, b in INI_BLOCKS if b.lstrip().startswith("[Unit]")]


def _ini(text: str) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read_string(text)
    return parser


def test_the_guide_shows_a_user_unit_and_its_autostart() -> None:
    assert UNITS, "the screens how-to shows a systemd user unit"
    assert any(b.lstrip().startswith("[Desktop Entry]") for _, b in INI_BLOCKS)


@pytest.mark.parametrize("page,block", UNITS, ids=[_rel(p) for p, _ in UNITS])
def test_unit_snippets_run_a_command_the_cli_accepts(page: Path, block: str) -> None:
    unit = _ini(block)
    assert {"Unit", "Service", "Install"} <= set(unit.sections())
    assert unit["Install"].get("WantedBy"), "an enabled unit needs WantedBy="
    argv = shlex.split(unit["Service"]["ExecStart"])
    assert argv[0] == "/opt/buddybot/.venv/bin/buddybot", "the install path of deploy/README.md"
    bb = buddybot_argv(argv)
    assert bb is not None
    check_buddybot(bb, full=True)
    assert unit["Service"].get("RestartPreventExitStatus") == "2", (
        "exit status 2 is a config error: restarting cannot fix it (as in deploy/systemd)")


@pytest.mark.integration
@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze")
@pytest.mark.parametrize("page,block", UNITS, ids=[_rel(p) for p, _ in UNITS])
def test_unit_snippets_pass_systemd_analyze_verify(page: Path, block: str,
                                                   tmp_path: Path) -> None:
    """systemd's own checker, with ExecStart pointed at this checkout's buddybot."""
    here = Path(sys.executable).parent / "buddybot"
    if not here.exists():
        pytest.skip("buddybot console script not installed next to this Python")
    unit = tmp_path / "buddybot-guide-snippet.service"
    unit.write_text(block.replace("/opt/buddybot/.venv/bin/buddybot", str(here)))
    done = subprocess.run(["systemd-analyze", "verify", str(unit)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0 and not done.stderr.strip(), done.stderr


def test_desktop_entries_start_the_user_unit_the_page_installs() -> None:
    for page, entry in INI_BLOCKS:
        if not entry.lstrip().startswith("[Desktop Entry]"):
            continue
        section = _ini(entry)["Desktop Entry"]
        assert section["Type"] == "Application" and section["Name"]
        started = re.findall(r"systemctl --user start ([\w.-]+)", section["Exec"])
        assert started, "the autostart entry starts the user unit"
        for name in started:
            assert f"~/.config/systemd/user/{name}" in page.read_text(encoding="utf-8"), (
                f"{_rel(page)}: {name} is not the unit the page installs")


ENV_FILE = ROOT / "deploy" / "systemd" / "env"


def test_env_lines_name_variables_of_the_shipped_env_file() -> None:
    known = set(re.findall(r"^#?(BUDDYBOT_[A-Z_]+)=", ENV_FILE.read_text(), re.M))
    lines = [line for page in SNIPPET_PAGES for block in _blocks(page, "text")
             if block.startswith("# /etc/buddybot/env")
             for line in block.splitlines()[1:] if line.strip()]
    assert lines, "the TLS how-to shows the router's line of /etc/buddybot/env"
    for line in lines:
        name, _, value = line.partition("=")
        assert name in known, f"{name}: not a variable of deploy/systemd/env"
        if name == "BUDDYBOT_ROUTER_ARGS":
            check_buddybot(["router", *shlex.split(value)], full=True)


REPO_PATH = re.compile(r"`((?:deploy|scripts|services|examples|benchmarks)/[\w./-]+)`")


@pytest.mark.parametrize("page", GUIDE, ids=_ids(GUIDE))
def test_repository_paths_the_pages_name_exist(page: Path) -> None:
    missing = [p for p in REPO_PATH.findall(page.read_text(encoding="utf-8"))
               if not (ROOT / p.rstrip("/")).exists()]
    assert not missing, f"{_rel(page)}: no such files {missing}"


def _requirement_names() -> set[str]:
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    specs = [*project["dependencies"], *(s for extra in project["optional-dependencies"].values()
                                         for s in extra)]
    return {re.split(r"[<>=!~\[; ]", spec, maxsplit=1)[0] for spec in specs}


def test_every_dependency_says_why_it_is_there() -> None:
    text = (DOCS / "dependencies.md").read_text(encoding="utf-8")
    rows = {m for line in text.splitlines() if line.startswith("| ")
            for m in re.findall(r"`([\w.-]+)`", line.split("|")[1])}
    missing = sorted(_requirement_names() - rows)
    assert not missing, f"docs/dependencies.md has no row for {missing}"
    assert "eclipse-zenoh" in rows and "pytest" in rows


USER_UNITS = {"buddybot-eyes-kiosk.service"}
"""Units a how-to writes out in full (a desktop user's), not shipped in deploy/systemd."""


@pytest.mark.parametrize("page", HOWTOS, ids=_ids(HOWTOS))
def test_units_the_pages_name_are_shipped(page: Path) -> None:
    named = set(re.findall(r"buddybot[\w.-]*\.(?:service|target)",
                           page.read_text(encoding="utf-8")))
    shipped = {p.name for p in (ROOT / "deploy" / "systemd").iterdir()}
    missing = sorted(named - shipped - USER_UNITS)
    assert not missing, f"{_rel(page)}: no such unit in deploy/systemd: {missing}"
