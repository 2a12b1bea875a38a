"""`buddybot.sdk.actions`: a Bot's action limit (pure: a fake clock, a probe-less
Diagnostics): the burst, then the rate, refused at once with the reason, counted;
marked `integration`, an app run by `buddybot app run` looping on expressions is
limited and counted in its diagnostics, and once killed (SIGKILL) its lease ends
holder_gone and the controller's own expression is back."""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.diagnostics import Diagnostics
from buddybot.runtime.node import Node
from buddybot.sdk import Refused
from buddybot.sdk.actions import ActionLimit, check_rate
from buddybot.tools.testing import Collector, Process, retry_until
from tests.cli.test_app import app_file, run_app


class Clock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def _limit(rate: float, burst: float) -> tuple[ActionLimit, Diagnostics, Clock]:
    diag = Diagnostics("app", 2.0, None, lambda: [])
    clock = Clock()
    return ActionLimit(diag, rate, burst, clock=clock), diag, clock


def test_actions_over_the_limit_are_refused_at_once_and_counted() -> None:
    limit, diag, clock = _limit(rate=4.0, burst=2.0)
    assert diag.values == {"actions": 0, "rate_limited": 0}  # shown before any action
    limit.take("express")
    limit.take("play")
    with pytest.raises(Refused, match=r"rate limited: say refused, more than 4 actions/s "
                       r"\(burst 2\)"):
        limit.take("say")
    clock.now += 0.25  # one token back
    limit.take("lease")
    with pytest.raises(Refused, match="rate limited"):
        limit.take("look_at")
    assert diag.values == {"actions": 3, "rate_limited": 2}
    assert diag.level == "WARN" and "over the limit" in diag.message
    clock.now += 5.0
    limit.take("express")
    assert diag.level == "WARN"  # still the same episode
    clock.now += 5.0
    limit.take("express")
    assert (diag.level, diag.message) == ("OK", "running")


def test_a_loop_gets_the_rate_and_no_more() -> None:
    limit, diag, clock = _limit(rate=20.0, burst=40.0)
    for _ in range(1000):  # 10 s of a loop asking every 10 ms
        with contextlib.suppress(Refused):
            limit.take("express")
        clock.now += 0.01
    assert 40 + 20 * 10 - 1 <= diag.values["actions"] <= 40 + 20 * 10 + 1
    assert diag.values["actions"] + diag.values["rate_limited"] == 1000


@pytest.mark.parametrize("rate, burst, why", [
    (0, 40, "actions_per_s"), (-1, 40, "actions_per_s"), (math.inf, 40, "actions_per_s"),
    (math.nan, 40, "actions_per_s"), (True, 40, "actions_per_s"), ("20", 40, "actions_per_s"),
    (1e9, 40, "actions_per_s"), (20, 0.5, "actions_burst"), (20, math.nan, "actions_burst"),
])
def test_an_absurd_limit_is_refused_naming_it(rate: object, burst: object, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        check_rate(rate, burst)  # type: ignore[arg-type]
    assert check_rate(20, 40) == (20.0, 40.0)


# --- a real app, controller and router ----------------------------------------------------


@pytest.mark.integration
def test_an_app_looping_on_actions_is_limited_counted_and_the_robot_resumes_when_killed(
        controller: Callable[[], Process], probe: Node, endpoint: str, log_dir: Path,
        tmp_path: Path) -> None:
    controller()
    expr = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    leases = Collector[m.Leases](probe, keys.LEASES)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="looper")
    path = app_file(tmp_path, "looper.py", """
        import time
        from buddybot.sdk import Refused
        class Looper:
            def run(self, bot, stop_event):
                told = False
                while not stop_event.is_set():
                    try:
                        bot.eyes.express("love")
                    except Refused as exc:
                        if not told:
                            print(f"looper: {exc}", flush=True)
                            told = True
                    time.sleep(0.002)
        """)
    started = time.monotonic()
    app = run_app(endpoint, log_dir, str(path))
    try:
        # The program's own limit and the controller's per-lease one are alike (20/s,
        # burst 40); under load the controller may see a burst squeezed by the
        # network and refuse first: either is the app being limited.
        app.wait_for_output("looper: rate limited: ", 30)
        expr.wait_for(lambda e: e.action == m.ExpressionAction.ANIMATE_LOVE, 30, "LOVE")
        counted = diag.wait_for(lambda d: int(d.values.get("rate_limited", 0)) > 0
                                and d.level == "WARN", 30,
                                "the app's diagnostics counting refusals, WARN")
        assert "over the limit" in counted.message
        elapsed = time.monotonic() - started
        assert 40 <= int(counted.values["actions"]) <= 40 + 20 * elapsed + 2, (
            counted.values, elapsed)
        holder = leases.wait_for(lambda s: any(lease.holder == "looper" for lease in s.leases),
                                 30, "the app's lease")
        lease_id = next(lease.lease_id for lease in holder.leases if lease.holder == "looper")
        resumed_from = len(expr.messages)
        app.kill()  # SIGKILL: no release, only the liveliness token's end
        leases.wait_for(lambda s: any(e.lease_id == lease_id and e.reason == "holder_gone"
                                      for e in s.ended), 30, "the lease ended holder_gone")
        retry_until(lambda: any(e.action == m.ExpressionAction.EYE_SLEEP
                                for e in expr.messages[resumed_from:]),
                    30, 0.05, "the controller's own EYE_SLEEP back on eyes/expression")
    finally:
        app.stop()
