"""The example apps of examples/apps/: their pure parts, and each end to end against
`buddybot up --sim` (the simulated radar's visitor walks in, stands ~20 s at 1 m and
leaves, every 38 s; the simulated camera shows a face)."""

from __future__ import annotations

import datetime
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

import pytest

from buddybot.apps import load_app
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until
from tests.system import robot

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "apps"
A = m.ExpressionAction


def example(name: str) -> ModuleType:
    module = sys.modules[load_app(str(EXAMPLES / f"{name}.py")).cls.__module__]
    return module


# --- pure parts ---------------------------------------------------------------------------


def test_each_example_is_one_app_named_after_its_file() -> None:
    for name in ("greeter", "love_after_10s", "wizard_of_oz"):
        assert load_app(str(EXAMPLES / f"{name}.py")).name == name


def test_the_greeting_depends_on_the_time_of_day() -> None:
    greeter = example("greeter")
    parts = [greeter.part_of_day(h) for h in range(24)]
    assert parts == ["night"] * 5 + ["morning"] * 7 + ["afternoon"] * 5 + ["evening"] * 5 \
        + ["night"] * 2
    lines = {greeter.line_for(datetime.datetime(2026, 1, 1, h)) for h in (8, 13, 19, 23)}
    assert len(lines) == 4


def test_wizard_commands() -> None:
    wizard = example("wizard_of_oz")
    parse, command = wizard.parse, wizard.Command
    assert parse("6") == command("express", "love")
    assert parse(" LOVE ") == command("express", "love")
    assert parse("left") == command("look", "left", wizard.GAZE_RAD, 0.0)
    assert parse("down").pitch < 0 and parse("centre").yaw == 0.0
    assert parse("say Hello there, friend") == command("say", "Hello there, friend")
    assert parse("say") == command("unknown", "say")
    assert parse("") is None and parse("q") == command("quit")
    assert parse("dance") == command("unknown", "dance")
    assert "say TEXT" in wizard.HELP


# --- against `up --sim` -------------------------------------------------------------------


RADAR_ONLY = ("radar-bridge", "radar-presence", "people", "controller", "eyes", "audio",
              "audio-player")


@contextmanager
def up_sim(tmp_path: Path, apps: list[Path], only: tuple[str, ...] = (),
           extra_config: str = "") -> Iterator[tuple[Process, Node, str]]:
    """`buddybot up --sim` with `apps` in `[apps]` (and `--only` these services when
    given): `robot.up_sim`, waiting for those services and the apps."""
    listed = ", ".join(f'"{a}"' for a in apps)
    selected = tuple(arg for name in only for arg in ("--only", name))
    services = len(only) or len([e for e in available_services() if not e.on_request])
    with robot.up_sim(tmp_path, f"[apps]\nrun = [{listed}]\n" + extra_config, selected,
                      services + len(apps)) as running:
        yield running


@pytest.mark.integration
@pytest.mark.robot
def test_greeter_says_the_line_of_the_time_of_day_to_an_arrival(tmp_path: Path) -> None:
    greeter = example("greeter")
    with up_sim(tmp_path, [EXAMPLES / "greeter.py"]) as (up, _probe, _endpoint):
        said = up.wait_for_output("greeter: person ", 180)
        line = next(x for x in said.splitlines() if "greeter: person " in x)
        hours = [datetime.datetime.now() - datetime.timedelta(minutes=2), datetime.datetime.now()]
        assert any(repr(greeter.line_for(h)) in line for h in hours), line
        assert line.endswith("(SUCCEEDED)"), line


@pytest.mark.integration
@pytest.mark.robot
def test_love_after_the_dwell_then_the_robots_own_eyes_when_the_visitor_left(
        tmp_path: Path) -> None:
    source = (EXAMPLES / "love_after_10s.py").read_text()
    assert "DWELL_S = 10.0\n" in source
    quick = tmp_path / "love_after_10s.py"
    quick.write_text(source.replace("DWELL_S = 10.0\n", "DWELL_S = 3.0\n"))
    # The simulated camera's face never leaves: the radar alone makes the visit here.
    with up_sim(tmp_path, [quick], RADAR_ONLY, "[people]\nabsence_hold_s = 1\n") as (
            up, probe, _endpoint):
        expression = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
        leases = Collector[m.Leases](probe, keys.LEASES)
        status = Collector[m.PlaySoundStatus](probe, keys.PLAY_SOUND_STATUS)
        up.wait_for_output("love_after_10s: person ", 100)
        expression.wait_for(lambda e: e.action == A.ANIMATE_LOVE, 30, "LOVE eyes")
        status.wait_for(lambda s: s.state == "SUCCEEDED", 60, "the sound played")
        assert any(lease.holder == "love_after_10s" for s in leases.messages
                   for lease in s.leases), leases.messages[-1:]
        up.wait_for_output("left; eyes released", 90)
        # The controller takes its eyes back: an expression of its own after LOVE.
        love_at = max(i for i, e in enumerate(expression.messages) if e.action == A.ANIMATE_LOVE)
        retry_until(lambda: any(e.action != A.ANIMATE_LOVE
                                for e in expression.messages[love_at + 1:]), 10, 0.1,
                    "the controller's own expression back")
        # leases/state of the release may follow the resumed expression on the wire.
        retry_until(lambda: not any(
            lease.holder == "love_after_10s" and "expression" in lease.resources
            for lease in leases.messages[-1].leases), 10, 0.1, "the app's lease ended")


@pytest.mark.integration
def test_wizard_of_oz_drives_eyes_gaze_and_voice_from_typed_lines(tmp_path: Path) -> None:
    with up_sim(tmp_path, []) as (_up, probe, endpoint):
        expression = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
        control = Collector[m.EyeControl](probe, keys.EYE_CONTROL)
        status = Collector[m.PlaySoundStatus](probe, keys.PLAY_SOUND_STATUS)
        wizard = subprocess.Popen(
            buddybot_argv("app", "run", str(EXAMPLES / "wizard_of_oz.py"), "--connect",
                          endpoint),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            assert wizard.stdin is not None and wizard.stdout is not None
            for line in ("star", "left", "say Hello from the wizard", "dance", "quit"):
                wizard.stdin.write(line + "\n")
                wizard.stdin.flush()
            out, _ = wizard.communicate(timeout=60)
            assert wizard.returncode == 0, out
        finally:
            if wizard.poll() is None:
                wizard.kill()
                wizard.wait(10)
        assert "express star: ok" in out and "look left: ok" in out, out
        assert "say Hello from the wizard: ok" in out and "unknown command 'dance'" in out, out
        expression.wait_for(lambda e: e.action == A.ANIMATE_STAR, 20, "STAR eyes")
        control.wait_for(lambda c: abs(c.yaw - 0.35) < 1e-6, 20, "gaze left")
        status.wait_for(lambda s: s.state in ("PLAYING", "SUCCEEDED"), 30, "the text spoken")
