"""The eye page in a real Chromium: follows gaze, closes lids, blinks, reconnects.

Data path in these tests is the real one: probe -> router -> eyes driver
process -> router -> eye-renderer process -> WebSocket -> page. Positions
are measured in screenshots (pixels), not read back from the page's
variables; the page's `window.eyes` is only used to wait for the
animation to settle. Screenshots of every expression are saved to
test-artifacts/eyes/ for a person to look at.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
    wait_port,
)

from ..conftest import ARTIFACTS, QUIET
from .conftest import screenshot

pytestmark = [pytest.mark.integration, pytest.mark.browser]

A = m.ExpressionAction
W, H = 640, 320
SHOTS = ARTIFACTS / "eyes"


def start_renderer(spawn: Callable[..., Process], port: int | None = None) -> tuple[Process, int]:
    """A renderer in the eyeball style: these tests measure its white sclera and
    black pupil (the glow style, the default, is tested in test_styles.py)."""
    port = port or free_port()
    proc = spawn("eye-renderer", "--port", str(port), "--no-browser", "--style", "eyeball")
    wait_port(port, 30)
    return proc, port


def open_page(browser: Any, port: int, eye: str = "left", extra: str = "&blink=0&saccade=0",
              width: int = W, height: int = H) -> Any:
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(f"http://127.0.0.1:{port}/eyes?eye={eye}{extra}")
    # Ready (socket open, renderer on the bus) and the connecting face faded out.
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002",
                           timeout=20_000)
    return page


def settled(page: Any, timeout_ms: int = 15_000) -> None:
    """Wait until every animated value is at its target (within a hair)."""
    page.wait_for_function(
        """() => {
          const e = window.eyes, c = e.cur, t = e.target, x = t.expression;
          const near = (a, b, tol) => Math.abs(a - b) < tol;
          return near(c.yaw, t.yaw, 0.05) && near(c.pitch, t.pitch, 0.05)
            && near(c.dilation, t.dilation, 0.2)
            && ["left", "right"].every(s => near(c.lids[s].top, t.lids[s].top, 0.1)
                                        && near(c.lids[s].bottom, t.lids[s].bottom, 0.1))
            && near(c.sad, x === 4 ? 1 : 0, 0.01) && near(c.grin, x === 3 ? 1 : 0, 0.01)
            && near(c.love, x === 6 ? 1 : 0, 0.01) && near(c.star, x === 7 ? 1 : 0, 0.01)
            && c.poseT >= 1 && c.poseTo === x && (t.distance !== null || c.verg < 0.01);
        }""", timeout=timeout_ms)


def shot(page: Any, name: str | None = None) -> np.ndarray:
    return screenshot(page, SHOTS, name)


def pupil_centre(img: np.ndarray) -> tuple[float, float]:
    """Centroid of the pure-black pupil pixels (background and lids are navy)."""
    mask = img.max(axis=2) < 12
    ys, xs = np.nonzero(mask)
    assert len(xs) > 50, "no pupil visible"
    return float(xs.mean()), float(ys.mean())


def sclera_pixels(img: np.ndarray) -> int:
    return int((img.min(axis=2) > 225).sum())


def dim_sclera_pixels(img: np.ndarray) -> int:
    """Sclera seen through the connecting face's dimming: a flat mid grey."""
    return int(((img.min(axis=2) > 90) & (img.max(axis=2) < 150)
                & (np.ptp(img, axis=2) < 20)).sum())


def colour_pixels(img: np.ndarray, bgr: tuple[int, int, int], tol: int = 30) -> int:
    return int((np.abs(img.astype(int) - np.array(bgr)).max(axis=2) < tol).sum())


def gaze(probe: Node, page: Any, yaw_deg: float, pitch_deg: float, stamp: int) -> None:
    """Publish eye control (radians) to the driver, as the built-in behaviour does,
    until the page has the new target."""
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    msg = m.EyeControl(stamp_ns=stamp, yaw=math.radians(yaw_deg), pitch=math.radians(pitch_deg),
                       target_distance_cm=120)

    def arrived() -> bool:
        pub.put(msg)
        target = page.evaluate("[window.eyes.target.yaw, window.eyes.target.pitch]")
        return abs(target[0] - yaw_deg) < 1e-6 and abs(target[1] - pitch_deg) < 1e-6

    retry_until(arrived, 20, 0.2, f"page target yaw {yaw_deg} pitch {pitch_deg}")
    settled(page)


def test_page_follows_published_direction(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    spawn("eyes")
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "left")
    cx0, cy0 = pupil_centre(shot(page))
    assert abs(cx0 - W / 2) < 6 and abs(cy0 - H / 2) < 6      # starts looking ahead

    gaze(probe, page, 30, 0, 1)
    # The eased commanded direction (the benchmarks' read-only hook) is there too.
    assert abs(page.evaluate("window.eyes.base.yaw") - 30) < 0.05
    x_left, _ = pupil_centre(shot(page, "direction_yaw+30"))
    gaze(probe, page, -30, 0, 2)
    x_right, _ = pupil_centre(shot(page, "direction_yaw-30"))
    # Robot's left (+yaw) -> pupil to the viewer's right (+x on screen).
    assert x_left > W / 2 + 20 and x_right < W / 2 - 20, (x_left, x_right)

    gaze(probe, page, 0, 20, 3)
    _, y_up = pupil_centre(shot(page))
    gaze(probe, page, 0, -20, 4)
    _, y_down = pupil_centre(shot(page))
    assert y_up < H / 2 - 15 and y_down > H / 2 + 15, (y_up, y_down)

    # Near -> large pupil, far -> small (the driver's curve), measured as black area.
    pupil_area = {}
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    for stamp, cm, expected in ((5, 35.0, 75.0 - 20.0 / 14), (6, 280.0, 32.5)):
        msg = m.EyeControl(stamp_ns=stamp, yaw=0.0, pitch=0.0, target_distance_cm=cm)

        def arrived(msg: m.EyeControl = msg, expected: float = expected) -> bool:
            pub.put(msg)
            return abs(page.evaluate("window.eyes.target.dilation") - expected) < 0.1

        retry_until(arrived, 20, 0.2, f"pupil target for {cm} cm")
        settled(page)
        pupil_area[cm] = int((shot(page, f"pupil_{int(cm)}cm").max(axis=2) < 12).sum())
    assert pupil_area[35.0] > 2 * pupil_area[280.0], pupil_area
    page.close()


def test_lids_close_on_sleep_and_open_on_awake(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    spawn("eyes")
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "both")
    open_white = sclera_pixels(shot(page))
    assert open_white > 0.1 * W * H
    expression = probe.publisher(keys.BEHAVIOUR_EXPRESSION)
    expression.put(m.ScreenExpression(stamp_ns=1, action=A.EYE_SLEEP))
    page.wait_for_function("window.eyes.target.lids.left.top === 50 "
                           "&& window.eyes.target.lids.right.bottom === 50", timeout=20_000)
    settled(page)
    assert sclera_pixels(shot(page)) < 0.002 * open_white
    expression.put(m.ScreenExpression(stamp_ns=2, action=A.EYE_AWAKE))
    page.wait_for_function("window.eyes.target.lids.left.top === 0", timeout=20_000)
    settled(page)
    assert sclera_pixels(shot(page)) > 0.95 * open_white
    page.close()


def test_screenshots_of_every_expression(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    spawn("eyes")
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "both")
    expression = probe.publisher(keys.BEHAVIOUR_EXPRESSION)
    images: dict[A, np.ndarray] = {}
    for stamp, action in enumerate(A, start=1):
        expression.put(m.ScreenExpression(stamp_ns=stamp, action=action))
        top = 50 if action == A.EYE_SLEEP else None
        page.wait_for_function(
            f"window.eyes.target.expression === {int(action)}"
            + (f" && window.eyes.target.lids.left.top === {top}" if top else ""),
            timeout=20_000)
        settled(page)
        images[action] = shot(page, f"{int(action)}_{action.name}")
    white = {a: sclera_pixels(img) for a, img in images.items()}
    awake = white[A.EYE_AWAKE]
    assert white[A.EYE_SLEEP] < 0.002 * awake
    for narrowed in (A.EYE_SLEEPY, A.EYE_GRIN, A.EYE_SAD):
        assert white[narrowed] < 0.9 * awake, narrowed.name
    assert white[A.EYE_SLEEPY] < white[A.EYE_SAD]
    # Hearts are red, stars gold, and the plain iris is gone in both.
    iris = (0xD0, 0x7F, 0x2F)  # #2f7fd0 as BGR
    assert colour_pixels(images[A.ANIMATE_LOVE], (0x5E, 0x24, 0xE0)) > 2000
    assert colour_pixels(images[A.ANIMATE_STAR], (0x00, 0xB4, 0xF5)) > 2000
    assert colour_pixels(images[A.EYE_AWAKE], iris) > 2000
    assert colour_pixels(images[A.ANIMATE_LOVE], iris) < 50
    assert colour_pixels(images[A.ANIMATE_STAR], iris) < 50
    # Sad lids slant: the outer corners (screen edges of the pair) droop.
    sad = images[A.EYE_SAD]
    col_outer = sad[:, W // 4 - 70].min(axis=1) > 225    # robot's right eye, outer side
    col_inner = sad[:, W // 4 + 70].min(axis=1) > 225    # same eye, inner side
    assert np.argmax(col_outer) > np.argmax(col_inner), "sad: outer corner should droop"
    page.close()


@QUIET  # blink and saccade durations
def test_page_blinks_and_saccades_on_its_own(
    browser: Any, spawn: Callable[..., Process]
) -> None:
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "both", extra="")
    # Two blinks (one gap) at the default interval: this test runs alone, and each
    # more blink would add 4.5 s on average to that phase.
    page.wait_for_function("window.eyes.stats.blinks >= 2", timeout=40_000)
    log = page.evaluate("window.eyes.blinkLog")
    # Closing ~60 ms, reopening slower; measured at frame granularity (a frame
    # delayed by a busy machine can only make a phase look longer), so the
    # faster blink is the one that shows the design.
    close_ms = min(b["close_ms"] for b in log if b["close_ms"] > 0)
    open_ms = min(b["open_ms"] for b in log if b["open_ms"] > 0)
    assert 50 <= close_ms <= 90, log
    assert open_ms > close_ms + 50, log
    # Every few seconds.
    gaps = [b["start_ms"] - a["start_ms"] for a, b in itertools.pairwise(log)]
    assert all(2000 <= gap <= 9000 for gap in gaps), gaps
    # Idle eyes make small saccades without any message.
    page.wait_for_function("Math.abs(window.eyes.cur.yaw) > 0.5 "
                           "|| Math.abs(window.eyes.cur.pitch) > 0.5", timeout=15_000)
    assert page.evaluate("window.eyes.stats.messages") >= 1   # only the hello
    page.close()


def test_look_random_looks_around(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "both", extra="&blink=0")
    probe.publisher(keys.EXPRESSION).put(
        m.ScreenExpression(stamp_ns=1, action=A.EYE_LOOK_RANDOM))
    page.wait_for_function("window.eyes.target.expression === 5", timeout=20_000)
    # Wanders well beyond the small idle saccades (+-3 degrees).
    page.wait_for_function("Math.abs(window.eyes.cur.yaw) > 6", timeout=20_000)
    page.close()


def test_page_reconnects_after_server_restart(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    spawn("eyes")
    proc, port = start_renderer(spawn)
    page = open_page(browser, port, "left")
    expression = probe.publisher(keys.BEHAVIOUR_EXPRESSION)   # one publisher: one latched value
    expression.put(m.ScreenExpression(stamp_ns=1, action=A.EYE_SLEEPY))
    page.wait_for_function("window.eyes.target.expression === 2", timeout=20_000)
    proc.stop()
    page.wait_for_function("!window.eyes.connected", timeout=20_000)
    # The page keeps animating while the server is away.
    frames = page.evaluate("window.eyes.stats.frames")
    page.wait_for_function(f"window.eyes.stats.frames > {frames + 10}", timeout=10_000)
    # Meanwhile the robot changes its mind; the new renderer gets it from the latched keys.
    expression.put(m.ScreenExpression(stamp_ns=2, action=A.EYE_GRIN))
    start_renderer(spawn, port)
    page.wait_for_function("window.eyes.connected && window.eyes.stats.connects >= 2",
                           timeout=30_000)
    page.wait_for_function("window.eyes.target.expression === 3 "
                           "&& window.eyes.target.lids.left.bottom === 28", timeout=20_000)
    gaze(probe, page, 25, 0, 10)
    x, _ = pupil_centre(shot(page))
    assert x > W / 2 + 15
    page.close()


def test_page_survives_malformed_messages(browser: Any, spawn: Callable[..., Process]) -> None:
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "left")
    before = page.evaluate("JSON.stringify(window.eyes.target)")
    style_before = page.evaluate("JSON.stringify(window.eyes.cfg.style)")
    junk = [
        "", "not json", "null", "42", "[]", '{"topic": "direction"}',
        '{"topic": "direction", "msg": {"yaw": "left", "pitch": 0}}',
        '{"topic": "direction", "msg": {"yaw": null, "pitch": 0}}',
        '{"topic": "lids", "msg": {"eye_id": 9, "top_lid_position": 50, '
        '"bottom_lid_position": 50}}',
        '{"topic": "expression", "msg": {"action": 99}}',
        '{"topic": "pupil", "msg": {"dilation_percentage": "big"}}',
        '{"topic": "unknown", "msg": {}}',
        # A style that is not one: wrong kind, a pose missing, a number as text.
        '{"topic": "hello", "msg": {"style": {"kind": "laser"}}}',
        '{"topic": "hello", "msg": {"style": {"kind": "glow", "background": "#000000", '
        '"color": "#00ffff", "poses": {}}}}',
        '{"topic": "hello", "msg": {"style": "glow"}}',
    ]
    for text in junk:
        page.evaluate("(t) => window.eyes.receive(t)", text)
    assert page.evaluate("window.eyes.stats.badMessages") == len(junk)
    assert page.evaluate("JSON.stringify(window.eyes.target)") == before
    assert page.evaluate("JSON.stringify(window.eyes.cfg.style)") == style_before
    # A distance that is not a number means "unknown": no vergence, the gaze still taken.
    page.evaluate("(t) => window.eyes.receive(t)",
                  '{"topic": "direction", "msg": {"yaw": 5, "pitch": 0, '
                  '"target_distance_cm": "near"}}')
    assert page.evaluate("[window.eyes.target.yaw, window.eyes.target.distance]") == [5, None]
    # Out-of-range but well-formed values are clamped, not trusted.
    page.evaluate("""(t) => window.eyes.receive(t)""",
                  '{"topic": "pupil", "msg": {"dilation_percentage": 1000}}')
    assert page.evaluate("window.eyes.target.dilation") == 100
    frames = page.evaluate("window.eyes.stats.frames")
    page.wait_for_function(f"window.eyes.stats.frames > {frames + 10}", timeout=10_000)
    page.close()


def test_both_page_puts_the_robots_left_eye_on_the_right_half(
    browser: Any, spawn: Callable[..., Process], probe: Node
) -> None:
    """Per-eye lids: closing only the robot's LEFT eye darkens the viewer's right half."""
    _proc, port = start_renderer(spawn)
    page = open_page(browser, port, "both")
    lids = probe.publisher(keys.LIDS)
    lids.put(m.EyeLidControl(stamp_ns=1, eye_id=m.EyeId.LEFT, top_lid_position=50,
                             bottom_lid_position=50))
    page.wait_for_function("window.eyes.target.lids.left.top === 50", timeout=20_000)
    settled(page)
    img = shot(page, "left_eye_closed_both_page")
    viewer_left, viewer_right = sclera_pixels(img[:, : W // 2]), sclera_pixels(img[:, W // 2:])
    assert viewer_right == 0 and viewer_left > 0.1 * W * H / 2, (viewer_left, viewer_right)
    # And the single-eye pages show their own eye.
    left_page = open_page(browser, port, "left")
    right_page = open_page(browser, port, "right")
    settled(left_page)
    settled(right_page)
    assert sclera_pixels(shot(left_page)) == 0
    assert sclera_pixels(shot(right_page)) > 0.1 * W * H
    for p in (page, left_page, right_page):
        p.close()


def test_page_shows_a_calm_connecting_face_until_the_bus_is_there(
    browser: Any, tmp_path: Any
) -> None:
    """Router down: the renderer still serves the page (it showed "connection
    refused" before), and the page shows its connecting face: half-closed,
    dimmed eyes looking ahead. Once a router is up: normal eyes. Router gone
    again: the connecting face again."""
    router_port = free_port()
    port = free_port()
    renderer = Process(buddybot_argv("run", "eye-renderer", "--connect",
                                     f"tcp/127.0.0.1:{router_port}", "--port", str(port),
                                     "--no-browser", "--style", "eyeball"),
                       "renderer-no-router", tmp_path)
    router: Router | None = None
    try:
        wait_port(port, 30)
        page = browser.new_page(viewport={"width": W, "height": H})
        page.goto(f"http://127.0.0.1:{port}/eyes?eye=both&blink=0&saccade=0")
        page.wait_for_function("window.eyes && window.eyes.connected", timeout=20_000)
        page.wait_for_function("window.eyes.cur.calm > 0.999 "
                               "&& Math.abs(window.eyes.cur.lids.left.top) < 0.01", timeout=20_000)
        assert page.evaluate("[window.eyes.ready, window.eyes.bus]") == [False, False]
        connecting = shot(page, "connecting")
        assert sclera_pixels(connecting) == 0                # nothing bright: dimmed
        dim = dim_sclera_pixels(connecting)
        assert dim > 0.05 * W * H, dim                       # but the eyes are there
        assert page.is_visible("#status")                    # and the grey dot says why
        # Half closed: no sclera in the top third of the eyes.
        top_rows = connecting[: int(H * 0.3)]
        assert dim_sclera_pixels(top_rows) == 0

        router = Router(port=router_port, log_dir=tmp_path)
        page.wait_for_function("window.eyes.ready && window.eyes.cur.calm < 0.002",
                               timeout=60_000)
        settled(page)
        awake = shot(page, "connected")
        assert sclera_pixels(awake) > 1.3 * dim, (sclera_pixels(awake), dim)  # lids open
        assert dim_sclera_pixels(awake) < 0.01 * W * H
        assert not page.is_visible("#status")

        router.stop()
        router = None
        page.wait_for_function("!window.eyes.ready && window.eyes.cur.calm > 0.999",
                               timeout=30_000)
        assert sclera_pixels(shot(page, "connecting_again")) == 0
        page.close()
    finally:
        if router is not None:
            router.stop()
        renderer.stop()
        print(renderer.output()[-3000:])
