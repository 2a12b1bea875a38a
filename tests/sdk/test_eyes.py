"""`buddybot.sdk.eyes`: expression names and aliases, gaze checks and the handle (pure),
and, marked `integration`, a real controller: an expression reaches `eyes/expression`,
a `for_s` lease expires and the controller's own expression comes back, a program
killed -9 while holding the eyes gives them back, a second program is refused naming
the first, an operator preempts an app."""

from __future__ import annotations

import asyncio
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import ALIASES, Bot, EyesHandle, Person, Refused, TimedOut
from buddybot.sdk.eyes import Eyes, expression_of, gaze_of, pupil_of
from buddybot.sdk.leases import Lease
from buddybot.tools.testing import Collector, Process

X = m.ExpressionAction

# --- pure ----------------------------------------------------------------------------------


def test_an_expression_is_named_by_its_action_its_name_or_an_alias() -> None:
    assert expression_of(X.ANIMATE_LOVE) is X.ANIMATE_LOVE
    assert expression_of("ANIMATE_LOVE") is X.ANIMATE_LOVE
    assert expression_of("love") is X.ANIMATE_LOVE
    assert expression_of("look_random") is X.EYE_LOOK_RANDOM
    assert sorted(ALIASES) == ["alert", "awake", "grin", "look_random", "love", "sad",
                               "sleep", "sleepy", "star"]
    assert {ALIASES[a] for a in ALIASES} == set(X)


@pytest.mark.parametrize("bad", ["LOVE", "happy", "", 6, None, "Love"])
def test_an_unknown_expression_lists_the_valid_names(bad: object) -> None:
    with pytest.raises(ValueError, match=r"unknown expression .*valid: awake, .*ANIMATE_STAR"):
        expression_of(bad)  # type: ignore[arg-type]


def test_gaze_values_are_checked_against_the_command_ranges() -> None:
    assert gaze_of(0.2, -0.1, None) == (0.2, -0.1, 0.0)
    assert gaze_of(0, 0, 1.5) == (0.0, 0.0, 150.0)
    for yaw, pitch, dist, why in ((4.0, 0.0, None, "yaw"), (0.0, float("nan"), None, "pitch"),
                                  ("0", 0.0, None, "yaw"), (0.0, 0.0, -1.0, "distance_m"),
                                  (0.0, 0.0, float("inf"), "distance_m"),
                                  (True, 0.0, None, "yaw")):
        with pytest.raises(ValueError, match=why):
            gaze_of(yaw, pitch, dist)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [-1, 100.5, float("nan"), True, "big"])
def test_a_pupil_size_is_a_percentage(bad: object) -> None:
    assert pupil_of(None) is None and pupil_of(90) == 90.0
    with pytest.raises(ValueError, match="pupil must be a percentage"):
        pupil_of(bad)  # type: ignore[arg-type]


def test_a_person_without_a_direction_is_refused_before_anything_is_sent() -> None:
    eyes = Eyes(None, None, 1.0)  # type: ignore[arg-type]  # nothing may be called
    person = Person(id=3, zone="social", engagement="engaging", seen_by="radar")
    with pytest.raises(Refused, match="person 3 has no direction yet"):
        eyes.look_at(person)
    with pytest.raises(ValueError, match="needs a pitch"):
        eyes.look_at(0.1)
    with pytest.raises(ValueError, match="duration_s must be > 0"):
        eyes.express("love", for_s=-1)


def test_a_handle_is_done_when_its_lease_ends_or_its_time_under_your_lease_is_up() -> None:
    lease = Lease(None, "L1", ("expression",), "app", None)
    implicit = EyesHandle("love", lease, implicit=True, for_s=None)
    timed = EyesHandle("star", lease, implicit=False, for_s=0.05)
    assert not implicit.done
    with pytest.raises(TimedOut, match=r"love still showing after 0\.01 s"):
        implicit.wait(0.01)
    assert timed.wait(5) == "elapsed" and lease.active
    lease.end("preempted", "taken by wizard")
    assert implicit.wait(0.01) == "preempted" and implicit.done
    assert asyncio.run(_awaited(implicit)) == "preempted"


def test_canceling_a_handle_under_your_own_lease_keeps_the_lease() -> None:
    lease = Lease(None, "L2", ("gaze",), "app", None)
    handle = EyesHandle("gaze", lease, implicit=False, for_s=None)
    assert handle.cancel() == "canceled" and handle.done and lease.active


async def _awaited(handle: EyesHandle) -> str:
    return await handle


# --- a real controller ---------------------------------------------------------------------


@pytest.fixture
def expr(probe: Node) -> Collector[m.ScreenExpression]:
    return Collector(probe, keys.EXPRESSION)


def _actions(expr: Collector[m.ScreenExpression]) -> list[X]:
    return [e.action for e in expr.messages]


@pytest.mark.integration
def test_express_shows_it_and_release_gives_the_eyes_back(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        expr: Collector[m.ScreenExpression], probe: Node) -> None:
    controller()
    control = Collector[m.EyeControl](probe, keys.EYE_CONTROL)
    bot = bot_factory()
    expr.clear()
    handle = bot.eyes.express("love")
    expr.wait_for(lambda e: e.action == X.ANIMATE_LOVE, 10, "ANIMATE_LOVE")
    assert handle.implicit and not handle.done
    again = bot.eyes.express(X.ANIMATE_STAR)
    assert again.lease is handle.lease  # one implicit lease, kept while held
    gaze = bot.eyes.look_at(0.3, -0.2, distance_m=1.0)
    control.wait_for(lambda c: abs(c.yaw - 0.3) < 1e-6 and abs(c.pitch + 0.2) < 1e-6, 10,
                     "the gaze asked for")
    assert gaze.lease is not handle.lease and gaze.lease.resources == ("gaze",)
    expr.clear()
    bot.eyes.release()
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, 10, "the controller's EYE_SLEEP back")
    assert handle.wait(5) == "released" and gaze.wait(5) == "released"
    bot.eyes.express("grin")  # the next action takes a new lease
    expr.wait_for(lambda e: e.action == X.EYE_GRIN, 10, "EYE_GRIN")


@pytest.mark.integration
def test_an_app_sets_the_pupils_with_its_gaze_or_alone(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        probe: Node) -> None:
    controller()
    pupil = Collector[m.PupilControl](probe, keys.PUPIL)
    bot = bot_factory()
    bot.eyes.look_at(0.1, 0.0, distance_m=3.0)  # far: the driver's curve gives 30 %
    pupil.wait_for(lambda p: p.dilation_percentage == pytest.approx(30.0), 10, "30 % at 3 m")
    bot.eyes.look_at(0.1, 0.0, distance_m=3.0, pupil=90)
    pupil.wait_for(lambda p: p.dilation_percentage == 90.0, 10, "90 % asked with the gaze")
    bot.eyes.pupils(15)
    pupil.wait_for(lambda p: p.dilation_percentage == 15.0, 10, "15 % asked alone")
    with pytest.raises(ValueError, match="percentage"):
        bot.eyes.pupils(101)


@pytest.mark.integration
def test_the_gaze_is_given_back_alone_and_the_expression_stays(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        expr: Collector[m.ScreenExpression], probe: Node) -> None:
    controller()
    control = Collector[m.EyeControl](probe, keys.EYE_CONTROL)
    bot = bot_factory()
    shown = bot.eyes.express("love")
    expr.wait_for(lambda e: e.action == X.ANIMATE_LOVE, 10, "ANIMATE_LOVE")
    gaze = bot.eyes.look_at(0.3, -0.2, distance_m=1.0)
    control.wait_for(lambda c: abs(c.yaw - 0.3) < 1e-6, 10, "the gaze asked for")
    control.clear()
    bot.eyes.release("gaze")
    # The built-in gaze (centre: nobody is there) comes back; LOVE stays.
    control.wait_for(lambda c: c.yaw == 0.0 and c.pitch == 0.0, 10, "the built-in gaze")
    assert gaze.wait(5) == "released" and not shown.done
    assert _actions(expr)[-1] == X.ANIMATE_LOVE
    with pytest.raises(ValueError, match="unknown part"):
        bot.eyes.release("pupils")
    bot.eyes.release("expression")
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, 10, "the controller's EYE_SLEEP back")


@pytest.mark.integration
def test_for_s_ends_on_the_controller_and_its_own_expression_comes_back(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        expr: Collector[m.ScreenExpression]) -> None:
    controller()
    bot = bot_factory()
    expr.clear()
    handle = bot.eyes.express("star", for_s=0.6)
    expr.wait_for(lambda e: e.action == X.ANIMATE_STAR, 10, "ANIMATE_STAR")
    assert handle.wait(10) == "expired"
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, 10, "EYE_SLEEP after expiry")
    assert _actions(expr)[-1] == X.EYE_SLEEP


@pytest.mark.integration
def test_a_second_program_is_refused_naming_the_first_and_an_operator_preempts(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        expr: Collector[m.ScreenExpression], operator_secret: str) -> None:
    controller()
    first = bot_factory(name="first_app")
    second = bot_factory(name="second_app")
    handle = first.eyes.express("love")
    with pytest.raises(Refused, match="expression is held by first_app at priority app"):
        second.eyes.express("sad")
    with pytest.raises(Refused, match="operator credential"):
        second.lease("eyes", priority="operator")  # a flag any program could set: no
    with second.lease("eyes", priority="operator", credential=operator_secret) as wizard:
        assert handle.wait(10) == "preempted" and handle.lease.ended == "preempted"
        assert "second_app" in handle.lease.end_message
        with pytest.raises(Refused, match="held by second_app at priority operator"):
            first.eyes.express("love")
        second.eyes.express("sad")
        expr.wait_for(lambda e: e.action == X.EYE_SAD, 10, "EYE_SAD under the operator")
        assert wizard.active
    assert wizard.ended == "released"
    first.eyes.express("grin")
    expr.wait_for(lambda e: e.action == X.EYE_GRIN, 10, "EYE_GRIN once released")


HOLDER = textwrap.dedent("""
    import sys, time
    from buddybot.sdk import Bot
    bot = Bot.connect(connect=[sys.argv[1]], name="doomed", timeout=10)
    bot.eyes.express("love")
    print("holding", flush=True)
    time.sleep(120)
""")


@pytest.mark.integration
def test_a_program_killed_while_holding_the_eyes_gives_them_back(
        controller: Callable[[], Process], endpoint: str, tmp_path: Path,
        expr: Collector[m.ScreenExpression], probe: Node) -> None:
    controller()
    leases = Collector[m.Leases](probe, keys.LEASES)
    script = tmp_path / "holder.py"
    script.write_text(HOLDER)
    app = Process([sys.executable, str(script), endpoint], "holder", tmp_path / "logs")
    try:
        app.wait_for_output("holding", 30)
        expr.wait_for(lambda e: e.action == X.ANIMATE_LOVE, 10, "the program's ANIMATE_LOVE")
        expr.clear()
        app.kill()
        expr.wait_for(lambda e: e.action == X.EYE_SLEEP, 10, "EYE_SLEEP after the kill")
        end = leases.wait_for(lambda s: any(e.holder == "doomed" for e in s.ended), 10,
                              "the lease's end")
        assert [e.reason for e in end.ended if e.holder == "doomed"] == ["holder_gone"]
    finally:
        app.stop()
