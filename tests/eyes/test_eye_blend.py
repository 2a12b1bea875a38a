"""A face that is alive: every change of expression blends (no jump cuts), the pupils
show the distance in both styles, and asleep or drowsy the eyes still breathe.

The renderer (and, for the pupils, the eyes driver) run as processes as in production;
the page runs in Debian's headless Chromium with Playwright's clock paused and stepped
one 60 Hz frame at a time, so every frame is taken at an exact moment of an animation
however busy the machine is. What is asserted is measured in the drawn pixels: the
canvas read back in the page, or screenshots.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import cv2
import msgspec
import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes import driver, styles, wire
from buddybot.eyes.settings import EyesSettings
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Process,
    free_port,
    paused_eye_page,
    retry_until,
    wait_port,
)

from ..conftest import ARTIFACTS
from .conftest import screenshot

pytestmark = [pytest.mark.integration, pytest.mark.browser]

A = m.ExpressionAction
STYLES = ["glow", "eyeball"]
FRAME_MS = 16
BREATH_MS = 4000
SHOTS = ARTIFACTS / "eyes-blend"
JUMP = 0.45
"""The most of a whole change one frame may draw. A blend over the built-in 280 ms
(cubic ease) draws at most ~0.2 of it in one frame, a cut all of it (1.0)."""

DIFF = """(first) => {
  const c = document.getElementById("eyes");
  const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
  const f = window.__blend || (window.__blend = {});
  const diff = (a, b) => {
    let sum = 0;
    for (let i = 0; i < a.length; i += 4) {
      sum += Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]);
    }
    return sum / (a.length / 4) / 3;
  };
  const out = first ? [0, 0] : [diff(f.prev, d), diff(f.first, d)];
  if (first) f.first = d;
  f.prev = d;
  return out;
}"""
"""Mean difference (0..255 per channel) of the canvas from the last frame read and from
the first one."""

RECORD = """([diff, count]) => {
  const measure = eval(diff);
  const steps = window.__steps = [];
  const tick = () => {
    steps.push(measure(false));
    if (steps.length < count) requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}"""
"""`DIFF` of each of the next `count` frames, taken in the page right after the page
drew each one (its own frame callback was asked for first), into `window.__steps`."""


def start(spawn: Callable[..., Process], style: str) -> int:
    port = free_port()
    spawn("eye-renderer", "--port", str(port), "--no-browser", "--style", style)
    wait_port(port, 30)
    return port


def receive(page: Any, topic: str, msg: dict[str, Any]) -> None:
    page.evaluate("(t) => window.eyes.receive(t)", json.dumps({"topic": topic, "msg": msg}))


def express(page: Any, action: A) -> None:
    """What the renderer forwards for an expression: the driver's lids, then it."""
    expression = m.ScreenExpression(stamp_ns=1, action=action)
    for msg in (*driver.lids_for_expression(expression), expression):
        page.evaluate("(t) => window.eyes.receive(t)",
                      wire.encode(wire.TOPIC_NAMES[type(msg)], msg))


def frames(page: Any, count: int) -> list[tuple[float, float]]:
    """(change from the frame before, change from the first) of the next `count`
    frames: recorded in the page, so a whole series costs one call, not one a frame."""
    page.evaluate(RECORD, [DIFF, count])
    page.clock.run_for(count * FRAME_MS)
    steps: list[list[float]] = page.evaluate("window.__steps")
    assert len(steps) == count, (len(steps), count)
    return [(a, b) for a, b in steps]


SETTLE_MS = 1000
"""Past its transition, how long an expression is left to come to rest before a
change from it is measured."""


def transition_ms(style: dict[str, Any], action: A) -> float:
    """How long the change to `action` takes in `style` (its pose's own, else the style's)."""
    ms: float = (style["poses"][styles.EXPRESSIONS[int(action)]]["transition_ms"]
                 or style["transition_ms"])
    return ms


def blend(page: Any, style: dict[str, Any], before: A, after: A) -> tuple[float, float, float]:
    """(the largest change one frame drew, the whole change, the change a frame draws
    at rest at either end: a beating heart, a turning star, a breath) of
    `before` -> `after`."""
    express(page, before)
    page.clock.run_for(transition_ms(style, before) + SETTLE_MS)
    page.evaluate(DIFF, True)
    rest = max(step for step, _ in frames(page, 6))
    express(page, after)
    steps = frames(page, math.ceil(transition_ms(style, after) / FRAME_MS) + 4)
    after_rest = max(step for step, _ in frames(page, 6))
    whole = page.evaluate(DIFF, False)[1]
    return max(step for step, _ in steps), whole, max(rest, after_rest)


def cut(largest: float, whole: float, rest: float) -> bool:
    """Whether one frame drew (nearly) the whole change: a jump cut."""
    return largest > JUMP * whole + 2 * rest


@pytest.mark.parametrize("style", STYLES)
def test_every_change_of_expression_blends(browser: Any, spawn: Callable[..., Process],
                                           style: str) -> None:
    """Every ordered pair of expressions (to and from the heart, the star and sleep
    included), and a live restyle to the other kind of drawing: no frame draws more
    than a fraction of the change. The same page with a style whose changes take no
    time is caught cutting (the check can fail)."""
    page = paused_eye_page(browser, start(spawn, style), 240, 120)
    spec = page.evaluate("window.eyes.cfg.style")
    assert spec["name"] == style
    cuts = []
    for before in A:
        for after in A:
            if before != after:
                largest, whole, rest = blend(page, spec, before, after)
                assert whole > 3.0, f"{before.name} -> {after.name} changed nothing ({whole:.2f})"
                if cut(largest, whole, rest):
                    cuts.append(f"{before.name} -> {after.name}: {largest:.1f} of {whole:.1f}")
    assert not cuts, f"{style}: jump cuts:\n" + "\n".join(cuts)

    # A live restyle to the other kind of drawing blends too.
    other = msgspec.to_builtins(styles.load().get(STYLES[1 - STYLES.index(style)]))
    express(page, A.EYE_AWAKE)
    page.clock.run_for(1000)
    page.evaluate(DIFF, True)
    rest = max(step for step, _ in frames(page, 6))
    receive(page, "hello", {"style": other})
    steps = frames(page, math.ceil(other["transition_ms"] / FRAME_MS) + 4)
    largest, whole = max(step for step, _ in steps), steps[-1][1]
    assert whole > 3.0 and not cut(largest, whole, rest), (largest, whole, rest)
    receive(page, "hello", {"style": spec})

    instant = {**spec, "transition_ms": 0,
               "poses": {k: {**p, "transition_ms": 0} for k, p in spec["poses"].items()}}
    receive(page, "hello", {"style": instant})
    for before, after in ((A.EYE_AWAKE, A.ANIMATE_LOVE), (A.EYE_AWAKE, A.EYE_SLEEP)):
        largest, whole, rest = blend(page, instant, before, after)
        assert cut(largest, whole, rest), (before.name, after.name, largest, whole, rest)
    page.close()


def eye_halves(img: np.ndarray) -> list[np.ndarray]:
    half = img.shape[1] // 2
    return [img[:, :half], img[:, half:]]


def glow_pupil(eye: np.ndarray) -> tuple[int, float, float]:
    """(dark pixels, their x, the eye's x) of a glow eye's pupil: the dark inside the
    lit shape that does not reach the outside (a heart's notch and the rounded
    corners do)."""
    lit = eye.max(axis=2) > 90
    xs = np.nonzero(lit)[1]
    if len(xs) < 30:
        return 0, 0.0, 0.0
    unlit = np.pad((~lit).astype(np.uint8), 1, constant_values=1)
    cv2.floodFill(unlit, None, (0, 0), 2)
    holes = np.nonzero(unlit[1:-1, 1:-1] == 1)[1]
    centre = float(xs.min() + xs.max()) / 2
    return len(holes), float(holes.mean()) if len(holes) else centre, centre


def eyeball_pupil(eye: np.ndarray) -> tuple[int, float, float]:
    """(black pixels, their x, the eyeball's x)."""
    dark = np.nonzero(eye.max(axis=2) < 12)
    ball = np.nonzero(eye.min(axis=2) > 225)[1]
    centre = float(ball.mean()) if len(ball) else 0.0
    return len(dark[1]), float(dark[1].mean()) if len(dark[1]) else 0.0, centre


def to_breath_top(page: Any) -> None:
    """Run the paused page to the next top of its slow breath (every 4 s on the server
    clock), where the sleeping glow's line is brightest: 1.4 s into the breath, parts
    of it dim below `glow_pupil`'s threshold and read as a hole (a "pupil" of 19 px)."""
    page.clock.run_for(math.ceil(page.evaluate(
        "() => (4000 - window.eyes.serverTime() % 4000) % 4000")) + 1)


def control(probe: Node, page: Any, stamp: int, yaw_deg: float, distance_cm: float) -> None:
    """Eye control through the eyes driver (as the built-in behaviour sends it) until
    the page has its gaze and the dilation the driver made of the distance; then
    the page's clock runs until the pupils have eased there."""
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    msg = m.EyeControl(stamp_ns=stamp, yaw=math.radians(yaw_deg), pitch=0.0,
                       target_distance_cm=distance_cm)

    def arrived() -> bool:
        pub.put(msg)
        got = page.evaluate("[window.eyes.target.yaw, window.eyes.target.distance]")
        return abs(got[0] - yaw_deg) < 1e-6 and got[1] == distance_cm

    retry_until(arrived, 20, 0.2, f"yaw {yaw_deg} at {distance_cm} cm on the page")
    dilation = driver.PupilCurve.from_points(EyesSettings().pupil_curve)(distance_cm)
    retry_until(lambda: page.evaluate("window.eyes.target.dilation") == pytest.approx(dilation),
                20, 0.1, "the driver's dilation on the page")
    page.clock.run_for(2000)


@pytest.mark.parametrize("style", STYLES)
def test_the_pupils_show_the_distance_at_a_small_screens_size(
        browser: Any, spawn: Callable[..., Process], probe: Node, style: str) -> None:
    """On a 320x240 screen (both eyes): a person at 30 cm makes each pupil at least
    2.5 times the area it is at 300 cm, and even then it is plainly there; it moves
    with the gaze inside the eye (glow) or with the iris (eyeball); asleep, and in
    love, there is none."""
    spawn("eyes")
    page = paused_eye_page(browser, start(spawn, style), 320, 240)
    measure = glow_pupil if style == "glow" else eyeball_pupil
    area = {}
    for stamp, cm in enumerate((300, 30), start=1):
        control(probe, page, stamp, 0, cm)
        img = screenshot(page, SHOTS, f"{style}_pupil_{cm}cm")
        area[cm] = [measure(eye)[0] for eye in eye_halves(img)]
    for eye in (0, 1):
        assert area[300][eye] > 60, area
        assert area[30][eye] > 2.5 * area[300][eye], area
    control(probe, page, 3, 30, 300)
    looking = screenshot(page, SHOTS, f"{style}_pupil_yaw+30")
    for eye in eye_halves(looking):
        _, pupil_x, eye_x = measure(eye)
        assert pupil_x > eye_x + 3, (pupil_x, eye_x)     # +yaw: the viewer's right
    for action in (A.EYE_SLEEP, A.ANIMATE_LOVE):
        express(page, action)
        page.clock.run_for(2500)
        to_breath_top(page)
        img = screenshot(page, SHOTS, f"{style}_pupil_{action.name}")
        assert [measure(eye)[0] for eye in eye_halves(img)] == [0, 0], action.name
    page.close()


def visible_rows(img: np.ndarray, style: str) -> int:
    """Rows of the eye showing any of it (the glow, or the eyeball's white)."""
    mask = img.max(axis=2) > 90 if style == "glow" else img.min(axis=2) > 225
    return int((mask.sum(axis=1) > 3).sum())


@pytest.mark.parametrize("style", STYLES)
def test_falling_asleep_is_slow_and_asleep_or_drowsy_the_eyes_breathe(
        browser: Any, spawn: Callable[..., Process], style: str) -> None:
    """AWAKE -> SLEEP: a quarter of a second in, the eye is still mostly open; 1.6 s
    in, it is shut. Over one slow breath a drowsy eye's top lid sinks and lifts
    again, and a sleeping eye (glow line, eyeball lash line) changes while it stays
    where it is."""
    page = paused_eye_page(browser, start(spawn, style), 240, 240, eye="left")

    def shot(name: str | None = None) -> np.ndarray:
        return screenshot(page, SHOTS, f"{style}_{name}" if name else None)

    express(page, A.EYE_AWAKE)
    page.clock.run_for(1000)
    awake = visible_rows(shot(), style)
    express(page, A.EYE_SLEEP)
    page.clock.run_for(250)
    assert visible_rows(shot("falling_asleep_250ms"), style) > 0.8 * awake
    page.clock.run_for(1350)
    assert visible_rows(shot("falling_asleep_1600ms"), style) < 0.15 * awake

    def over_a_breath() -> list[np.ndarray]:
        out = []
        for _ in range(BREATH_MS // 250):
            page.clock.run_for(250)
            out.append(shot().astype(float))
        return out

    asleep = over_a_breath()
    lit = [float(img.max(axis=2).mean()) for img in asleep]
    change = max(float(np.abs(img - asleep[0]).mean()) for img in asleep)
    assert change > 0.3, (change, lit)
    columns = [float(np.nonzero(img.max(axis=2) > 40)[1].mean()) for img in asleep]
    assert max(columns) - min(columns) < 1.0, columns        # nothing moves sideways

    express(page, A.EYE_SLEEPY)
    page.clock.run_for(1500)
    rows = [visible_rows(img.astype(np.uint8), style) for img in over_a_breath()]
    assert max(rows) - min(rows) >= 4, rows
    page.close()
