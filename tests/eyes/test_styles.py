"""Eye styles (services/eyes/styles.py): as data, pure (the built-in file, user files,
errors), and in a real Chromium: every expression distinct, gaze, lids, vergence, restyling.

The browser tests run real processes as in production (router, eyes driver, eye-renderer
with `--style`), the page in Debian's headless Chromium. Everything asserted there is
measured in screenshots (pixels); `window.eyes` only says when the
animation has arrived. Screenshots of every expression in each style are
saved under the artifacts folder (BUDDYBOT_ARTIFACTS, else test-artifacts/)
in eyes-styles/ for a person to look at (docs/images/eyes-contact-sheet.png
is made the same way by scripts/eyes_contact_sheet.py).
"""

from __future__ import annotations

import itertools
import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes import driver, styles, wire
from buddybot.eyes.settings import EyeRendererSettings
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    NO_PINGS,
    Process,
    buddybot_argv,
    clock_time,
    free_port,
    retry_until,
    wait_port,
)

from ..conftest import ARTIFACTS, QUIET
from .conftest import screenshot

A = m.ExpressionAction
W, H = 480, 240
SHOTS = ARTIFACTS / "eyes-styles"
STYLES = ["glow", "eyeball"]
DISTINCT = 3.0
"""Mean absolute difference (0..255, over every pixel and channel) two
expressions' screenshots must at least have; the closest built-in pairs
are ~6 (eyeball GRIN / SAD) and ~8 (glow AWAKE / LOOK_RANDOM), the same
pose twice ~0."""


def start(spawn: Callable[..., Process], style: str) -> int:
    port = free_port()
    spawn("eye-renderer", "--port", str(port), "--no-browser", "--style", style)
    wait_port(port, 30)
    return port


def open_page(browser: Any, port: int, eye: str = "both", clock: bool = False) -> Any:
    """The page with no blinks or saccades of its own; with `clock`, on Playwright's
    clock (running as the real one until `at_breath_top` stops it)."""
    page = browser.new_page(viewport={"width": W, "height": H})
    if clock:
        page.clock.install()
    page.goto(f"http://127.0.0.1:{port}/eyes?eye={eye}&blink=0&saccade=0")
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002",
                           timeout=20_000)
    return page


def settled(page: Any) -> None:
    """The pose change is over and gaze, lids and vergence are at their targets."""
    page.wait_for_function(
        """() => {
          const e = window.eyes, c = e.cur, t = e.target, near = (a, b) => Math.abs(a - b) < 0.05;
          return c.poseT >= 1 && c.poseTo === t.expression
            && near(c.yaw, t.yaw) && near(c.pitch, t.pitch)
            && Math.abs(c.verg - e.vergenceGoal()) < 0.003
            && Math.abs(c.rest - (t.expression === 1 ? 1 : 0)) < 0.003
            && ["left", "right"].every(s => near(c.lids[s].top, t.lids[s].top)
                                        && near(c.lids[s].bottom, t.lids[s].bottom));
        }""", timeout=15_000)


def shot(page: Any, name: str | None = None) -> np.ndarray:
    return screenshot(page, SHOTS, name)


def express(probe: Node, page: Any, action: A, stamp: int) -> None:
    """Publish an expression (the driver adds its lids) and wait until it is drawn."""
    probe.publisher(keys.BEHAVIOUR_EXPRESSION).put(m.ScreenExpression(stamp_ns=stamp,
                                                                      action=action))
    # The driver's lids come on their own topic, maybe after the expression.
    lids = driver.DEFAULT_LIDS[action].left
    page.wait_for_function(
        f"window.eyes.target.expression === {int(action)} "
        f"&& window.eyes.target.lids.left.top === {lids.top} "
        f"&& window.eyes.target.lids.right.bottom === {lids.bottom}", timeout=20_000)
    settled(page)


def look(page: Any, yaw: float, pitch: float, distance_cm: float | None = None) -> None:
    """A direction message as the renderer forwards it (with the driver's
    target_distance_cm when given), straight into the page."""
    msg: dict[str, Any] = {"stamp_ns": 1, "yaw": yaw, "pitch": pitch}
    if distance_cm is not None:
        msg["target_distance_cm"] = distance_cm
    page.evaluate("(t) => window.eyes.receive(t)", json.dumps({"topic": "direction", "msg": msg}))
    settled(page)


def at_breath_top(page: Any) -> None:
    """Stop the page's clock at the next top of the slow breath (4 s, on the server
    clock the page has learnt), where a drowsy top lid is highest, and draw that
    frame: shots taken there differ by the gaze alone, however long a shot takes on
    a busy machine. `page.clock.resume()` lets the page run on.

    The page stops asking the server's time first: a pong read on a stopped clock
    would move its server clock estimate, and the breath with it."""
    page.evaluate(NO_PINGS)
    top = page.evaluate("""() => {
      let wait = (4000 - window.eyes.serverTime() % 4000) % 4000;
      if (wait < 1000) wait += 4000;
      return Date.now() + wait;
    }""")
    page.clock.pause_at(clock_time(top))
    page.clock.run_for(16)


def eye_mask(img: np.ndarray, style: str) -> np.ndarray:
    """What moves with the gaze: the glowing shape, or the eyeball's black pupil."""
    if style == "glow":
        return img.max(axis=2) > 90
    return img.max(axis=2) < 12


def centroid_x(mask: np.ndarray) -> float:
    xs = np.nonzero(mask)[1]
    assert len(xs) > 30, "nothing to measure"
    return float(xs.mean())


def visible_height(img: np.ndarray, style: str) -> int:
    """Rows of the robot's right eye (viewer's left half) showing any eye: glow or sclera."""
    half = img[:, : W // 2]
    mask = half.max(axis=2) > 90 if style == "glow" else half.min(axis=2) > 225
    return int((mask.sum(axis=1) > 3).sum())


@pytest.mark.integration
@pytest.mark.browser
@pytest.mark.parametrize("style", STYLES)
def test_every_expression_looks_different(browser: Any, spawn: Callable[..., Process],
                                          probe: Node, style: str) -> None:
    spawn("eyes")
    page = open_page(browser, start(spawn, style))
    images = {}
    for stamp, action in enumerate(A, start=1):
        express(probe, page, action, stamp)
        images[action] = shot(page, f"{style}_{styles.EXPRESSIONS[int(action)]}").astype(float)
    for a, b in itertools.combinations(A, 2):
        diff = float(np.abs(images[a] - images[b]).mean())
        assert diff > DISTINCT, f"{style}: {a.name} and {b.name} look alike ({diff:.2f})"
    # Hearts are pink-red, stars yellow: the colour of the shape, not only its outline.
    love, star = images[A.ANIMATE_LOVE], images[A.ANIMATE_STAR]
    assert ((love[..., 2] > 180) & (love[..., 1] < 120)).sum() > 1500
    assert ((star[..., 2] > 180) & (star[..., 1] > 150) & (star[..., 0] < 120)).sum() > 1500
    # Asleep: almost nothing lit (a glow style shows a thin line, an eyeball a lash line).
    awake_lit = (images[A.EYE_AWAKE].max(axis=2) > 90).sum()
    assert (images[A.EYE_SLEEP].max(axis=2) > 90).sum() < 0.1 * awake_lit
    page.close()


@pytest.mark.integration
@pytest.mark.browser
@pytest.mark.parametrize("style", STYLES)
def test_gaze_moves_the_eyes_and_lids_follow(browser: Any, spawn: Callable[..., Process],
                                             probe: Node, style: str) -> None:
    spawn("eyes")
    page = open_page(browser, start(spawn, style), clock=True)
    look(page, 0, 0)
    x0 = centroid_x(eye_mask(shot(page), style))
    look(page, 30, 0)
    robot_left = shot(page, f"{style}_yaw+30")
    look(page, -30, 0)
    robot_right = shot(page, f"{style}_yaw-30")
    # +yaw is the robot's left: the viewer's right (+x).
    assert centroid_x(eye_mask(robot_left, style)) > x0 + 15
    assert centroid_x(eye_mask(robot_right, style)) < x0 - 15
    if style == "glow":
        # Curiosity: the eye on the side looked at is the larger one.
        lit = robot_left.max(axis=2) > 90
        assert lit[:, W // 2:].sum() > 1.1 * lit[:, : W // 2].sum()
    # Drowsy lids follow the gaze: looking up shows more eye than looking down.
    express(probe, page, A.EYE_SLEEPY, 1)
    look(page, 0, 25)
    at_breath_top(page)
    up = visible_height(shot(page, f"{style}_sleepy_up"), style)
    page.clock.resume()
    look(page, 0, -25)
    at_breath_top(page)
    down = visible_height(shot(page, f"{style}_sleepy_down"), style)
    assert up > down + 4, (up, down)
    page.close()


@pytest.mark.integration
@pytest.mark.browser
@pytest.mark.parametrize("style", STYLES)
def test_grin_and_sleepy_lids_narrow_the_eye(browser: Any, spawn: Callable[..., Process],
                                             probe: Node, style: str) -> None:
    spawn("eyes")
    page = open_page(browser, start(spawn, style))
    heights = {}
    for stamp, action in enumerate((A.EYE_AWAKE, A.EYE_GRIN, A.EYE_SLEEPY), start=1):
        express(probe, page, action, stamp)
        heights[action] = visible_height(shot(page), style)
    awake = heights[A.EYE_AWAKE]
    assert awake > 0.3 * H, heights
    assert heights[A.EYE_GRIN] < 0.85 * awake, heights
    assert heights[A.EYE_SLEEPY] < 0.8 * awake, heights
    page.close()


@pytest.mark.integration
@pytest.mark.browser
@pytest.mark.parametrize("style", STYLES)
def test_a_near_person_makes_the_eyes_converge(browser: Any, spawn: Callable[..., Process],
                                               style: str) -> None:
    page = open_page(browser, start(spawn, style))

    def eye_gap() -> float:
        mask = eye_mask(shot(page), style)
        return (centroid_x(mask[:, W // 2:]) + W // 2) - centroid_x(mask[:, : W // 2])

    look(page, 0, 0, 300)
    far = eye_gap()
    look(page, 0, 0, 30)
    near = eye_gap()
    look(page, 0, 0, None)     # distance unknown: no vergence
    unknown = eye_gap()
    assert near < far - 8, (near, far)
    assert abs(unknown - far) < 1.5, (unknown, far)
    page.close()


@pytest.mark.integration
@pytest.mark.browser
def test_asleep_only_the_glow_breathes(browser: Any, spawn: Callable[..., Process],
                                       probe: Node) -> None:
    spawn("eyes")
    page = open_page(browser, start(spawn, "glow"))
    express(probe, page, A.EYE_SLEEP, 1)
    look(page, 30, 10)                         # asleep, the eyes do not follow
    brightness, columns = [], []
    for _ in range(9):                         # 4 s: one breath at ~0.25 Hz
        img = shot(page).astype(float)
        brightness.append(img.max(axis=2).mean())
        columns.append(centroid_x(img.max(axis=2) > 40))
        page.wait_for_timeout(500)
    assert max(brightness) > 1.15 * min(brightness), brightness
    assert max(columns) - min(columns) < 1.0, columns    # nothing else moves
    assert abs(columns[0] - W / 2) < 2.0, columns           # resting in the middle
    page.close()


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


@pytest.mark.integration
@pytest.mark.browser
def test_a_live_style_change_restyles_the_page(browser: Any, spawn: Callable[..., Process],
                                               endpoint: str) -> None:
    port = start(spawn, "glow")
    page = open_page(browser, port)
    settled(page)
    white = int((shot(page).min(axis=2) > 225).sum())
    assert page.evaluate("window.eyes.cfg.style.kind") == "glow" and white < 50

    def changed() -> bool:
        result = param(endpoint, "set", "eye-renderer", "style", '"eyeball"')
        return result.returncode == 0

    retry_until(changed, 30, 0.5, "eye-renderer params")
    page.wait_for_function("window.eyes.cfg.style.kind === 'eyeball'", timeout=20_000)
    settled(page)
    # `settled` does not wait for a restyle's cross-fade (the old look fading out over
    # the new one): a shot in its last frames shows the white dimmed under 225. Shots
    # are taken until the fade is over, the eyeball showing within 10 s.
    blank = []

    def eyeball_shown() -> bool:
        white = int((shot(page, "live_restyled_eyeball").min(axis=2) > 225).sum())
        if white <= 0.1 * W * H:
            blank.append(white)
        return white > 0.1 * W * H

    retry_until(eyeball_shown, 10, 0.2, "the eyeball's white on the restyled page")
    print(f"shots in the cross-fade: {len(blank)} (white pixels {blank})")
    assert page.evaluate("window.eyes.stats.connects") == 1      # restyled in place

    refused = param(endpoint, "set", "eye-renderer", "style", '"sparkly"')
    assert refused.returncode == 1
    assert "no such style (known: eyeball, glow)" in refused.stderr
    assert page.evaluate("window.eyes.cfg.style.kind") == "eyeball"
    page.close()


@pytest.mark.integration
@pytest.mark.browser
def test_the_driver_passes_the_distance_and_the_eyes_converge(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    """End to end: eyes/control's target_distance_cm -> driver -> eyes/direction ->
    renderer -> page, measured as the gap between the two glowing eyes."""
    spawn("eyes")
    page = open_page(browser, start(spawn, "glow"))
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    gaps = {}
    for stamp, cm in enumerate((300, 30), start=1):
        control = m.EyeControl(stamp_ns=stamp, yaw=0.0, pitch=0.0, target_distance_cm=cm)

        def arrived(control: m.EyeControl = control, cm: int = cm) -> bool:
            pub.put(control)
            return bool(page.evaluate("window.eyes.target.distance") == cm)

        retry_until(arrived, 20, 0.2, f"distance {cm} cm on the page")
        settled(page)
        mask = eye_mask(shot(page), "glow")
        gaps[cm] = (centroid_x(mask[:, W // 2:]) + W // 2) - centroid_x(mask[:, : W // 2])
    assert gaps[30] < gaps[300] - 8, gaps
    page.close()


@pytest.mark.integration
@pytest.mark.browser
@QUIET  # the shape at a moment of an animation: a busy machine draws that frame late
def test_a_glow_blink_squashes_and_stretches(browser: Any, spawn: Callable[..., Process],
                                             tmp_path: Any) -> None:
    """Halfway through a (slowed-down) blink the glow eye is flatter and wider."""
    cfg = tmp_path / "eyes.toml"      # no spontaneous blink in the way
    cfg.write_text("[eye_renderer]\nblink_interval_min_s = 60\nblink_interval_max_s = 120\n")
    port = free_port()
    spawn("eye-renderer", "--port", str(port), "--no-browser", "--config", str(cfg))
    wait_port(port, 30)
    page = browser.new_page(viewport={"width": W, "height": H})
    page.goto(f"http://127.0.0.1:{port}/eyes?eye=left&saccade=0")
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002",
                           timeout=20_000)
    settled(page)

    def box() -> tuple[int, int]:
        ys, xs = np.nonzero(shot(page).max(axis=2) > 90)
        return int(np.ptp(xs)), int(np.ptp(ys))

    width0, height0 = box()
    start = page.evaluate("window.eyes.serverTime()") + 300
    blink = {"kind": "blink", "start_ms": start, "duration_ms": 3000,
             "params": {"close_ms": 1500, "open_ms": 1500, "cause": "test"}}
    page.evaluate("(t) => window.eyes.receive(t)", json.dumps({"topic": "motion", "msg": blink}))
    page.wait_for_function(f"window.eyes.serverTime() > {start + 1100}", timeout=10_000)
    width, height = box()
    assert height < 0.75 * height0, (height, height0)
    assert width > width0 + 4, (width, width0)
    page.close()


# --- styles as data -------------------------------------------------------------------


def write(tmp_path: Path, data: Any) -> Path:
    path = tmp_path / "styles.json"
    path.write_text(json.dumps(data))
    return path


def test_the_built_in_file_loads_with_both_styles_and_glow_is_the_default() -> None:
    library = styles.load()
    assert {"glow", "eyeball"} <= set(library.names)
    assert library.get("glow").kind == "glow" and library.get("eyeball").kind == "eyeball"
    assert EyeRendererSettings().style == "glow"


def test_every_expression_has_its_own_pose_in_each_built_in_style() -> None:
    """Named in the file itself (not only inherited from the base), and no two alike."""
    specs = styles.builtin_specs()
    assert tuple(a.name.split("_", 1)[1] for a in m.ExpressionAction) == styles.EXPRESSIONS
    for name, style in styles.load().styles.items():
        assert set(specs[name]["poses"]) == set(styles.EXPRESSIONS), name
        poses = [msgspec.to_builtins(style.poses[e]) for e in styles.EXPRESSIONS]
        for i, a in enumerate(poses):
            for b in poses[i + 1:]:
                assert a != b, (name, a)


def test_the_key_poses_say_what_the_issue_asks_for() -> None:
    for style in styles.load().styles.values():
        p = style.poses
        assert p["LOVE"].shape == "heart" and p["STAR"].shape == "star"
        assert p["GRIN"].bottom_lid_curve > 50                  # happy crescent
        assert p["SAD"].top_lid_angle > 0                       # outer corners down
        assert p["SLEEPY"].top_lid >= 30                        # drowsy half lids
        assert p["SLEEP"].breathe > 0                           # slow breathing glow
        assert p["AWAKE"].shape == "eye" and p["AWAKE"].top_lid == 0


@pytest.mark.parametrize(("pose", "message"), [
    ({"top_lid": 101}, "styles.glow.poses.GRIN.top_lid: expected <= 100"),
    ({"top_lid": -1}, "styles.glow.poses.GRIN.top_lid: expected >= 0"),
    ({"top_lid_angle": 60}, "styles.glow.poses.GRIN.top_lid_angle: expected <= 45"),
    ({"width": "wide"}, "styles.glow.poses.GRIN.width: expected `float`, got `str`"),
    ({"color": "red"}, "styles.glow.poses.GRIN.color"),
    ({"shape": "square"}, "styles.glow.poses.GRIN.shape"),
    ({"wiggle": 3}, "styles.glow.poses.GRIN: object contains unknown field `wiggle`"),
])
def test_a_bad_pose_value_is_refused_naming_its_key(tmp_path: Path, pose: dict[str, Any],
                                                     message: str) -> None:
    path = write(tmp_path, {"styles": {"glow": {"poses": {"GRIN": pose}}}})
    with pytest.raises(ConfigError) as refused:
        styles.load(path)
    assert str(refused.value).startswith(f"{path}: {message}"), str(refused.value)


@pytest.mark.parametrize(("data", "message"), [
    ({"styles": {"glow": {"poses": {"GIGGLE": {}}}}},
     "styles.glow.poses.GIGGLE: unknown expression (known: AWAKE, SLEEP"),
    ({"styles": {"glow": {"reach": 150}}}, "styles.glow.reach: expected <= 100"),
    ({"styles": {"glow": {"kind": "neon"}}}, "styles.glow.kind"),
    ({"styles": {"glow": {"blinky": True}}}, "styles.glow: object contains unknown field"),
    ({"styles": {"glow": {"base": {"glow": 200}}}}, "styles.glow.base.glow: expected <= 100"),
    ({"styles": {"mine": {"color": "#ffffff"}}}, "styles.mine: missing kind"),
    ({"styles": {"mine": {"extends": "nope"}}}, "styles.mine.extends = 'nope': no such style"),
    ({"styles": {"a": {"extends": "b"}, "b": {"extends": "a"}}}, "styles.a.extends: a loop"),
    ({"styles": {"bad name": {"extends": "glow"}}}, "styles.bad name: a style name is"),
    ({"looks": {}}, "a style file is an object with one key"),
    ({"styles": []}, "styles: expected an object"),
])
def test_a_bad_style_file_is_refused_naming_the_key(tmp_path: Path, data: Any,
                                                     message: str) -> None:
    path = write(tmp_path, data)
    with pytest.raises(ConfigError) as refused:
        styles.load(path)
    assert message in str(refused.value) and str(path) in str(refused.value)


def test_not_json_and_no_file_are_config_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(ConfigError, match="not valid JSON"):
        styles.load(bad)
    with pytest.raises(ConfigError, match="cannot read style file"):
        styles.load(tmp_path / "missing.json")


def test_a_user_file_adds_a_style_and_changes_a_built_in_one(tmp_path: Path) -> None:
    path = write(tmp_path, {"styles": {
        "ember": {"extends": "glow", "color": "#ff8a1f", "base": {"glow": 90},
                  "poses": {"GRIN": {"bottom_lid": 45}}},
        "eyeball": {"poses": {"SAD": {"top_lid_angle": 30}}},
    }})
    builtin = styles.load()
    library = styles.load(path)
    assert set(library.names) == set(builtin.names) | {"ember"}
    ember, glow = library.get("ember"), builtin.get("glow")
    assert ember.kind == "glow" and ember.color == "#ff8a1f"
    assert ember.poses["GRIN"].bottom_lid == 45
    assert ember.poses["GRIN"].bottom_lid_curve == glow.poses["GRIN"].bottom_lid_curve
    assert all(ember.poses[e].glow == 90 for e in styles.EXPRESSIONS)   # its base: all poses
    assert ember.poses["LOVE"].shape == "heart"                          # inherited
    # The built-in eyeball changed in one value, everything else kept.
    eyeball = library.get("eyeball")
    assert eyeball.poses["SAD"].top_lid_angle == 30
    assert eyeball.poses["GRIN"] == builtin.get("eyeball").poses["GRIN"]
    assert eyeball.background == builtin.get("eyeball").background
    assert library.get("glow") == glow


def test_a_complete_new_style_needs_no_parent(tmp_path: Path) -> None:
    glow = styles.load().get("glow")
    fields = {k: getattr(glow, k) for k in styles.STYLE_FIELDS}
    base = msgspec.to_builtins(glow.poses["AWAKE"])
    path = write(tmp_path, {"styles": {"plain": {**fields, "base": base}}})
    plain = styles.load(path).get("plain")
    assert all(plain.poses[e] == glow.poses["AWAKE"] for e in styles.EXPRESSIONS)
    del base["shape"]
    write(tmp_path, {"styles": {"plain": {**fields, "base": base}}})
    with pytest.raises(ConfigError, match=r"styles\.plain\.poses\.AWAKE: missing shape"):
        styles.load(path)


def test_the_style_setting_must_name_a_known_style() -> None:
    library = styles.load()
    with pytest.raises(ConfigError) as refused:
        library.get("sparkly")
    text = str(refused.value)
    assert "eye_renderer.style = 'sparkly'" in text
    assert "known: eyeball, glow" in text


def test_the_hello_carries_the_whole_style() -> None:
    style = styles.load().get("glow")
    hello = wire.Hello(iris_color="#2f7fd0", max_yaw_deg=40.0, max_pitch_deg=30.0,
                       server_id="x", style=style)
    msg = json.loads(wire.encode("hello", hello))["msg"]
    assert msg["style"]["kind"] == "glow"
    assert set(msg["style"]["poses"]) == set(styles.EXPRESSIONS)
    assert msg["style"]["poses"]["LOVE"]["shape"] == "heart"


@pytest.mark.integration
def test_the_renderer_refuses_to_start_with_an_unknown_style_or_a_bad_file(
        tmp_path: Path) -> None:
    """Exit status 2 (not restarted) with the key in the message, before serving."""
    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(buddybot_argv("run", "eye-renderer", "--no-browser", "--port", "0",
                                            "--connect", "tcp/127.0.0.1:1", *args),
                              capture_output=True, text=True, timeout=60)

    unknown = run("--style", "sparkly")
    assert unknown.returncode == 2, unknown.stderr
    assert "eye_renderer.style = 'sparkly': no such style (known: eyeball, glow)" in unknown.stderr
    path = write(tmp_path, {"styles": {"glow": {"poses": {"GRIN": {"top_lid": 101}}}}})
    bad = run("--style-file", str(path))
    assert bad.returncode == 2, bad.stderr
    assert "styles.glow.poses.GRIN.top_lid: expected <= 100" in bad.stderr
    assert "Traceback" not in bad.stderr + unknown.stderr
    # Tracebacks (RecursionError) or gigabytes before: one line each, exit 2.
    hostile = {"nested": ('{"styles": {"a": ' + "[" * 100_000 + "]" * 100_000 + "}}",
                          "not valid JSON: nested deeper than 32 levels (line 1)"),
               "chain": (json.dumps({"styles": chain(200)}),
                         "styles.s0.extends: a chain longer than 16 styles"),
               "big": (json.dumps({"styles": {f"s{i}": {"extends": "glow"}
                                              for i in range(20_000)}}),
                       "a style file is at most 256 kB: not read")}
    for name, (text, expected) in hostile.items():
        path = tmp_path / f"{name}.json"
        path.write_text(text)
        result = run("--style-file", str(path))
        assert result.returncode == 2, result.stderr
        last = result.stderr.strip().splitlines()[-1]
        assert last == f"buddybot: config error: {path}: {expected}"
        assert "Traceback" not in result.stderr


def chain(n: int) -> dict[str, Any]:
    """n styles each extending the next, the last one glow: resolved from the top,
    the whole chain is walked at once."""
    found: dict[str, Any] = {f"s{i}": {"extends": f"s{i + 1}"} for i in range(n - 1)}
    found[f"s{n - 1}"] = {"extends": "glow", "color": "#ff8000"}
    return found


def test_extends_chains_and_style_counts_are_bounded(tmp_path: Path) -> None:
    library = styles.load(write(tmp_path, {"styles": chain(styles.MAX_EXTENDS)}))
    assert library.get("s0").color == "#ff8000"
    with pytest.raises(ConfigError, match=r"styles\.s0\.extends: a chain longer than 16 styles"):
        styles.load(write(tmp_path, {"styles": chain(styles.MAX_EXTENDS + 1)}))
    with pytest.raises(ConfigError, match="257 styles, at most 256"):
        styles.load(write(tmp_path, {"styles": {f"s{i}": {"extends": "glow"}
                                                for i in range(257)}}))
    loop = {"a": {"extends": "b"}, "b": {"extends": "c"}, "c": {"extends": "b"}}
    with pytest.raises(ConfigError, match=r"styles.b.extends: a loop \(b -> c -> b\)"):
        styles.load(write(tmp_path, {"styles": loop}))
