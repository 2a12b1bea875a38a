"""The dashboard page in a real Chromium, fed real messages through a real router.

probe -> router -> dashboard process -> WebSocket -> page. What the page
drew is read back from its canvases' pixels (face box, radar bars) or its
DOM (presence, nodes), never from the page's own variables alone.
"""

from __future__ import annotations

import math
import statistics
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, free_port, wait_port

from ..conftest import ARTIFACTS

pytestmark = [pytest.mark.integration, pytest.mark.browser]

W, H = 1280, 800
SHOTS = ARTIFACTS / "dashboard"


def start_dashboard(spawn: Callable[..., Process], *args: str) -> int:
    port = free_port()
    spawn("dashboard", "--port", str(port), *args)
    wait_port(port, 30)
    return port


def open_page(browser: Any, port: int) -> Any:
    page = browser.new_page(viewport={"width": W, "height": H})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.errors = errors
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function("document.getElementById('conn').textContent === 'on the bus'",
                           timeout=30_000)
    return page


def sensor_frame(moving: list[int], still: list[int], device: int = 7,
                 moving_cm: int = 140) -> m.LD2410TargetDataFrameArray:
    return m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=device, sensors=[
        m.LD2410TargetDataFrame(
            radar_id=0, target_state=m.TargetState.MOVING_AND_STATIONARY,
            movement_distance=moving_cm, movement_energy=60, stationary_distance=150,
            stationary_energy=35, detection_distance=150, max_moving_gate=8,
            max_stationary_gate=8, moving_gate_energy=moving, stationary_gate_energy=still)])


def test_face_box_is_drawn_over_the_image_at_the_face_pixels(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    images = probe.publisher(keys.CAMERA_IMAGE, camera="front")
    faces = probe.publisher(keys.FACES, camera="front")
    pixels = np.zeros((480, 640, 3), np.uint8)
    pixels[:] = (40, 90, 200)  # BGR: an orange-red scene
    box = m.FaceBox(x0=200, y0=150, x1=320, y1=290, score=0.93, followed=True,
                    keypoints=[m.PixelPoint(x=235, y=200), m.PixelPoint(x=285, y=200)])
    detections = m.FaceDetections(
        stamp_ns=m.now_ns(), frame_id="cam", width=640, height=480, faces=[box],
        distance_m=0.62, cues=[m.DistanceCue(name="width", distance_m=0.6, weight=0.7,
                                             status="used")])

    def publish_until_drawn() -> None:
        for _ in range(300):
            images.put(m.Image(stamp_ns=m.now_ns(), frame_id="cam", width=640, height=480,
                               encoding="bgr8", data=pixels.tobytes()))
            faces.put(detections)
            if page.evaluate("!!(window.dash.image && window.dash.faces)"):
                return
            time.sleep(0.05)
        raise TimeoutError("the page never got both an image and faces")

    publish_until_drawn()
    page.evaluate("drawCamera()")
    rgba = page.evaluate("""() => {
        const c = document.getElementById('camera');
        const g = c.getContext('2d');
        const at = (x, y) => Array.from(g.getImageData(x, y, 1, 1).data);
        return {size: [c.width, c.height], left: at(200, 220), right: at(320, 250),
                top: at(260, 150), inside: at(260, 260), outside: at(120, 400),
                eye: at(235, 200)};
    }""")
    assert rgba["size"] == [640, 480]
    green = (63, 185, 80)   # the followed face's box colour
    scene = (200, 90, 40)   # the image, as RGB after JPEG
    for where in ("left", "right", "top"):
        assert np.abs(np.array(rgba[where][:3]) - green).max() < 30, (where, rgba[where])
    for where in ("inside", "outside"):
        assert np.abs(np.array(rgba[where][:3]) - scene).max() < 25, (where, rgba[where])
    assert rgba["eye"][:3] == [255, 79, 216]  # a keypoint dot
    # Text is written at most 4 times a second (the page's own rule): wait for it.
    page.wait_for_function("document.getElementById('faces').innerText.includes('0.62 m')",
                           timeout=10_000)
    text = page.inner_text("#faces")
    assert "0.62 m" in text and "width 0.60 m (weight 0.70)" in text
    assert page.errors == []


def test_radar_bars_match_the_published_energies(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    radar = probe.publisher(keys.RADAR_FRAMES, device="7")
    moving = [5, 15, 25, 35, 45, 55, 65, 75, 95]
    still = [90, 80, 70, 60, 50, 40, 30, 20, 10]
    radar.put(sensor_frame(moving, still))
    page.wait_for_function("window.dash.sensors['7/0'] && window.dash.sensors['7/0'].last",
                           timeout=20_000)
    page.evaluate("drawBars(window.dash.sensors['7/0'])")
    heights = page.evaluate("""() => {
        const c = document.querySelector('[data-sensor="7/0"] .bars');
        const g = c.getContext('2d'), geo = window.dashBars(c.width, c.height);
        const data = g.getImageData(0, 0, c.width, c.height).data;
        const out = [[], []];
        for (let gate = 0; gate < 9; gate++) for (const which of [0, 1]) {
            const x = Math.round(geo.x(gate, which) + geo.bw / 2);
            let n = 0;  // coloured pixels up from the baseline
            for (let y = Math.floor(geo.base) - 1; y > 0; y--) {
                const i = (y * c.width + x) * 4;
                const [r, gr, b] = [data[i], data[i + 1], data[i + 2]];
                const bar = which ? (b > 200 && r < 120) : (r > 200 && b < 100);
                if (!bar) break;
                n++;
            }
            out[which].push(Math.round(n / geo.ph * 100));
        }
        return out;
    }""")
    print("bar heights (moving, still):", heights)
    assert np.abs(np.array(heights[0]) - moving).max() <= 2
    assert np.abs(np.array(heights[1]) - still).max() <= 2
    # Basic mode (no gate energies) is said, not drawn as empty bars.
    basic = sensor_frame(moving, still)
    basic.sensors[0].moving_gate_energy = basic.sensors[0].stationary_gate_energy = None
    radar.put(basic)
    page.wait_for_function("window.dash.sensors['7/0'].last.moving_gates === null",
                           timeout=20_000)
    assert page.errors == []


def test_a_presence_change_is_shown_within_300_ms(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    presence = probe.publisher(keys.PRESENCE)
    figures = []
    for i in range(6):
        state = m.PresenceState.IN_RANGE if i % 2 == 0 else m.PresenceState.OUT_OF_RANGE
        distance = 1.0 + i / 10
        text = f"{state.name} {distance:.2f} m"
        page.evaluate("""(text) => {
            window.seen = null;
            const el = document.getElementById('presence');
            const obs = new MutationObserver(() => {
                if (el.textContent === text && window.seen === null) {
                    window.seen = Date.now(); obs.disconnect();
                }
            });
            obs.observe(el, {childList: true, characterData: true, subtree: true});
        }""", text)
        sent = time.time() * 1000
        presence.put(m.PresenceDetection(stamp_ns=m.now_ns(), target_state=m.PresenceTarget.MOVING,
                                         presence_state=state, distance_m=distance))
        page.wait_for_function("window.seen !== null", timeout=20_000)
        figures.append(page.evaluate("window.seen") - sent)
    print("presence publish -> DOM change, ms:", [round(f) for f in figures],
          f"median {statistics.median(figures):.0f}")
    assert statistics.median(figures) < 300
    assert max(figures) < 1000
    assert page.errors == []


def test_a_killed_node_is_shown_down_and_its_restart_counted(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    port = start_dashboard(spawn)
    presence = spawn("radar-presence", "--range-m", "1.7")
    page = open_page(browser, port)
    row = "#nodes tr[data-node='radar-presence']"
    page.wait_for_function(f"""() => {{
        const r = document.querySelector("{row}");
        return r && r.children[1].textContent === 'alive';
    }}""", timeout=30_000)
    # Its live parameters reach the page (range and holds on the distance plot).
    page.wait_for_function(
        "document.getElementById('rules').textContent.startsWith('range 1.70 m')",
        timeout=30_000)
    presence.kill()
    page.wait_for_function(f"""() => {{
        const r = document.querySelector("{row}");
        return r.children[1].textContent === 'down' && r.children[1].className === 'down';
    }}""", timeout=15_000)
    spawn("radar-presence")
    page.wait_for_function(f"""() => {{
        const r = document.querySelector("{row}");
        return r.children[1].textContent === 'alive' && r.children[2].textContent === '1';
    }}""", timeout=30_000)
    assert page.errors == []


def wait_leases(leases: Collector[m.Leases], predicate: Callable[[m.Leases], bool],
                what: str) -> m.Leases:
    """The newest `leases/state` matching `predicate` (waiting for one)."""
    return leases.wait_for(lambda s: predicate(s) and s is leases.messages[-1], 20, what)


def test_operator_control_drives_the_eyes_through_the_controller_and_breaks_leases(
        browser: Any, spawn: Callable[..., Process], probe: Node,
        node_factory: Callable[..., Node]) -> None:
    """Router + eyes driver + controller + dashboard: the switch takes an operator
    lease, the buttons act under it (the arbiter publishes), switching off gives the
    eyes back, and the lease panel breaks an app's lease."""
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    controls = Collector[m.EyeControl](probe, keys.EYE_CONTROL)
    leases = Collector[m.Leases](probe, keys.LEASES)
    spawn("eyes")
    spawn("controller")
    own = expressions.wait_for(timeout=30, what="the controller's own expression").action
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    page.wait_for_function("window.dash.leases && window.dash.leases.known", timeout=20_000)
    # Until the operator takes control the buttons are disabled and say why.
    grin = "button[data-expression='EYE_GRIN']"
    assert page.is_disabled(grin)
    assert "take control first" in page.get_attribute(grin, "title")
    assert page.is_disabled("button[data-gaze='left']")

    page.click("label.switch")
    state = wait_leases(leases, lambda s: any(x.holder == "dashboard" for x in s.leases),
                        "the dashboard's lease in leases/state")
    held = next(x for x in state.leases if x.holder == "dashboard")
    assert held.priority == "operator" and held.expires_ns is None
    assert sorted(held.resources) == ["audio", "expression", "gaze"]
    page.wait_for_function("document.getElementById('control').checked", timeout=10_000)
    row = f"#leases div[data-lease='{held.lease_id}']"
    page.wait_for_selector(row, timeout=10_000)
    assert page.inner_text(f"{row} .prio-operator") == "operator"
    own_id = page.evaluate("window.dash.leases.own")
    assert own_id == held.lease_id, own_id  # the page knows its lease by the public id only

    page.click(grin)
    expressions.wait_for(lambda e: e.action == m.ExpressionAction.EYE_GRIN, 15,
                         "EYE_GRIN on eyes/expression (published by the arbiter)")
    page.wait_for_function("document.getElementById('expression').textContent === 'EYE_GRIN'",
                           timeout=15_000)
    page.click("button[data-gaze='left']")
    controls.wait_for(lambda c: abs(c.yaw + 0.5) < 1e-6 and c.pitch == 0.0, 15,
                      "the robot looking to its right")
    # No audio service runs: the page says so, and the dashboard lives on.
    page.click("button[data-sound='greeting']")
    page.wait_for_function(
        "document.getElementById('reply').textContent.startsWith('play greeting:')",
        timeout=20_000)
    assert "bad" in page.get_attribute("#reply", "class")

    # Switched off: the lease ends "released" and the controller's expression is back.
    expressions.clear()
    page.click("label.switch")
    wait_leases(leases, lambda s: not s.leases and any(
        e.lease_id == held.lease_id and e.reason == "released" for e in s.ended),
        "the operator lease released")
    expressions.wait_for(lambda e: e.action == own, 15, f"the controller's {own.name} again")
    page.wait_for_function("!document.getElementById('control').checked", timeout=10_000)
    assert page.is_disabled(grin)

    # An app's lease appears in the panel; Break ends it "broken".
    app = node_factory("greeter")
    reply = leasing.ask(app, m.LeaseRequest(
        holder="greeter", instance=app.instance, resources=["expression"], duration_s=60),
        timeout=10)
    assert reply.granted, reply
    public = m.public_lease_id(reply.lease_id)  # what the page and the bus show
    app_row = f"#leases div[data-lease='{public}']"
    page.wait_for_selector(app_row, timeout=15_000)
    assert page.inner_text(f"{app_row} .holder") == "greeter"
    assert page.inner_text(f"{app_row} .expires").startswith("expires in ")
    page.click(f"{app_row} button.break")
    broken = wait_leases(leases, lambda s: any(
        e.lease_id == public for e in s.ended), "the app's lease broken")
    end = next(e for e in broken.ended if e.lease_id == public)
    assert (end.reason, end.message) == ("broken", "broken by operator (by dashboard)")
    page.wait_for_selector(f"#leases-ended div[data-ended='{public}']", timeout=10_000)
    assert "broken" in page.inner_text(f"#leases-ended div[data-ended='{public}']")
    page.wait_for_selector(app_row, state="detached", timeout=10_000)
    assert page.errors == []


def operator_takes_over_an_app(page: Any, endpoint: str) -> None:
    """An app holds the eyes; the operator takes control (the app's lease ends
    `preempted`, shown in the panel) and grins; the screenshot
    (docs/images/dashboard-operator.png is a copy of one) shows both."""
    app = Node("greeter", connect=[endpoint])
    try:
        reply = leasing.ask(app, m.LeaseRequest(
            holder="greeter", instance=app.instance, resources=["expression", "gaze"],
            duration_s=600), timeout=10)
        assert reply.granted, reply
        public = m.public_lease_id(reply.lease_id)
        page.wait_for_selector(f"#leases div[data-lease='{public}']", timeout=15_000)
        page.click("label.switch")
        page.wait_for_selector(f"#leases-ended div[data-ended='{public}']",
                               timeout=15_000)
        assert "preempted" in page.inner_text(f"#leases-ended div[data-ended='{public}']")
        page.click("button[data-expression='EYE_GRIN']")
        page.wait_for_function(
            "document.getElementById('expression').textContent === 'EYE_GRIN'", timeout=15_000)
        page.wait_for_timeout(1500)  # the eye page in its frame grins (a picture only)
        page.screenshot(path=str(SHOTS / "dashboard-operator.png"), full_page=True)
        size = page.evaluate("[document.documentElement.scrollWidth, "
                             "document.documentElement.scrollHeight]")
        assert size[0] <= W and size[1] <= H, f"the page needs scrolling at {W}x{H}: {size}"
    finally:
        app.close()


def test_the_whole_simulated_robot_on_one_laptop_screen(browser: Any, tmp_path: Path) -> None:
    """`buddybot up --sim` with the dashboard open at 1280x800: every panel has live
    content; the screenshot is saved for a person to look at (docs/images/dashboard.png
    is a copy of one); then the operator takes control from an app."""
    eye_port, dash_port, router_port = free_port(), free_port(), free_port()
    config = tmp_path / "robot.toml"
    config.write_text(f"[eye_renderer]\nport = {eye_port}\n\n[dashboard]\nport = {dash_port}\n"
                      "\n[audio_player]\nbackend = \"null\"\n\n[camera]\nfps = 15\n")
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--listen", f"tcp/127.0.0.1:{router_port}",
                               "--status-period", "0"), "up", tmp_path)
    try:
        wait_port(dash_port, 60)
        wait_port(eye_port, 60)
        page = open_page(browser, dash_port)
        # Live content everywhere: a face on the image, 10 s of radar lines, presence
        # rules, the controller's state, gaze, every node alive.
        page.wait_for_function("""() => {
            const d = window.dash;
            const nodes = d.nodes || [];
            return d.image && d.faces && d.faces.faces.length > 0
                && Object.values(d.sensors).some((s) => s.points.length > 50
                    && s.points[s.points.length - 1][0] - s.points[0][0] > 10)
                && d.rules && d.controller && d.presence
                && document.getElementById('gaze').textContent !== '–'
                && nodes.length >= 9 && nodes.every((n) => n.alive);
        }""", timeout=120_000)
        page.wait_for_timeout(1500)  # let the eye page in its frame settle (a picture only)
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "dashboard.png"), full_page=True)
        size = page.evaluate("[document.documentElement.scrollWidth, "
                             "document.documentElement.scrollHeight]")
        assert size[0] <= W and size[1] <= H, f"the page needs scrolling at {W}x{H}: {size}"
        operator_takes_over_an_app(page, f"tcp/127.0.0.1:{router_port}")
        assert page.errors == []
    finally:
        up.stop(30)
        print(up.output()[-3000:])


# --- the angle radars' map -------------------------------------------------------------

MAP_COLOURS = [(0xff, 0xa6, 0x57), (0x79, 0xc0, 0xff)]
"""The page's first two sensor colours (dashboard.js MAP_COLOURS)."""
DRAWN = """() => {
    window.dashMap();
    const v = window.dash.map, c = document.getElementById('map'), g = c.getContext('2d');
    const at = (p) => Array.from(g.getImageData(Math.round(p[0]), Math.round(p[1]), 1, 1).data);
    return {origin: v.origin, scale: v.scale, size: [c.width, c.height],
            targets: v.sensors[0].targets.map((t) => ({at: t.at, rgba: at(t.at)})),
            shown: !document.getElementById('map-box').hidden,
            plots: !document.getElementById('sensors').hidden};
}"""
"""The map redrawn now, and each target's place and pixel colour on the canvas."""


def radar_targets(points: list[tuple[float, float]], device: int = 4) -> m.RadarTargets:
    """An angle-radar report with targets at camera-frame (x, y) points (sensor at the
    camera, facing forward: its own x is the robot's right)."""
    targets = [m.RadarTarget(
        slot=i, x_m=-y, y_m=x, speed_mps=0.3, resolution_m=0.32,
        position=m.Point(x=x, y=y, z=0.0), bearing_rad=math.atan2(y, x),
        distance_m=math.hypot(x, y)) for i, (x, y) in enumerate(points)]
    return m.RadarTargets(stamp_ns=m.now_ns(), device_id=device, radar_id=0, targets=targets)


def walk(step: int) -> list[tuple[float, float]]:
    """Three people at report `step` (10 per second): one crossing from the robot's
    left, one coming closer on its right, one almost standing far ahead."""
    t = step / 10
    return [(2.0, 1.3 - 0.35 * t), (3.0 - 0.3 * t, -1.4 + 0.05 * t),
            (4.2 + 0.03 * math.sin(3 * t), 0.6 + 0.04 * t)]


def serve_params(probe: Node, node: str, values: dict[str, Any]) -> None:
    """Answer `params/<node>` as that service would (op "list"), from the probe."""
    infos = [m.ParamInfo(name=k, value=v, type="", range="", live=True) for k, v in values.items()]
    probe.serve(keys.PARAMS, lambda _req: m.ParamReply(node=node, table=node.replace("-", "_"),
                                                       params=infos), node=node)


def test_the_map_shows_the_angle_radar_targets_published_on_the_bus(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    """Three LD2450 targets with trails, an ignore zone (radar-presence's live
    `zones`), the camera's view (fx from the config over the faces' width) and
    the followed person: each target is drawn where its camera-frame position
    says (read from the canvas' pixels), and the screenshot is kept
    (docs/images/dashboard-map.png is a copy of one)."""
    serve_params(probe, "radar-presence", {
        "range_m": 2.0, "zones": [{"name": "TV", "mode": "ignore", "x": [2.6, 3.6],
                                   "y": [1.6, 2.6]}]})
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    faces = probe.publisher(keys.FACES, camera="front")
    faces.put(m.FaceDetections(stamp_ns=m.now_ns(), frame_id="cam", width=640, height=480))
    probe.publisher(keys.CONTROLLER_STATE).put(m.ControllerState(
        stamp_ns=m.now_ns(), phase="engaged", in_range=True, person_id=3))
    radar = probe.publisher(keys.RADAR_TARGETS, device="4")
    people = probe.publisher(keys.PEOPLE_STATE)
    step = 0

    def report(advance: bool = True) -> None:
        """The walk's next step, or (advance False) its last one again, freshly stamped."""
        nonlocal step
        now = m.now_ns()
        pts = walk(step if advance else step - 1)
        radar.put(radar_targets(pts))
        x, y = pts[0]
        people.put(m.PeopleState(stamp_ns=now, people=[m.Person(
            id=3, distance_m=math.hypot(x, y), zone="SOCIAL", seen_by="RADAR",
            zone_since_ns=now, arrived_ns=now, engagement="ENGAGED", engagement_since_ns=now,
            yaw_rad=math.atan2(y, x))]))
        step += 1 if advance else 0

    # Two and a half seconds of walking (trails), until the page has all of it.
    deadline = time.monotonic() + 60
    while step < 25 or not page.evaluate("""() => {
            const v = window.dash.map;
            return v && v.sensors.length === 1 && v.sensors[0].targets.length === 3
                && v.zones.length === 1 && v.fov && v.people.some((p) => p.followed);
        }"""):
        assert time.monotonic() < deadline, "the page never got the whole map"
        report()
        time.sleep(0.1)
    # The last step is held (put again, fresh) while the canvas is read: unrefreshed,
    # its targets would age out of the map on a machine too busy to read it at once.
    holding = threading.Event()

    def hold() -> None:
        while not holding.wait(0.1):
            report(advance=False)

    holder = threading.Thread(target=hold, daemon=True)
    holder.start()
    deadline = time.monotonic() + 30
    try:
        drawn = page.evaluate(DRAWN)
        while len(drawn["targets"]) != 3:
            assert time.monotonic() < deadline, f"the map lost its targets: {drawn}"
            time.sleep(0.1)
            drawn = page.evaluate(DRAWN)
    finally:
        holding.set()
        holder.join(5)
    assert drawn["shown"] and not drawn["plots"]
    ou, ov = drawn["origin"]
    for (x, y), target in zip(walk(step - 1), drawn["targets"], strict=True):
        # x forward drawn up, y (the robot's left) drawn left, one scale.
        expected = (ou - y * drawn["scale"], ov - x * drawn["scale"])
        assert np.abs(np.array(target["at"]) - expected).max() < 2.0, (target, (x, y))
        assert np.abs(np.array(target["rgba"][:3]) - MAP_COLOURS[0]).max() < 10, target
    # The walk goes on while the page is read: stopped, its targets would age
    # out of the map before a loaded machine gets to the text.
    walking = threading.Event()

    def walk_on() -> None:
        while not walking.wait(0.1):
            report()

    walker = threading.Thread(target=walk_on, daemon=True)
    walker.start()
    try:
        page.wait_for_function(
            "document.getElementById('map-info').textContent.includes('following person 3')",
            timeout=10_000)
        info = page.inner_text("#map-info")
        assert "3 targets" in info and "camera view 56°" in info, info
        assert "zones from params/radar-presence" in info, info
        page.wait_for_function("(window.dash.nodes || []).some((n) => n.name === 'dashboard' "
                               "&& n.alive)", timeout=20_000)
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "dashboard-map.png"), full_page=True)
    finally:
        walking.set()
        walker.join(5)
    size = page.evaluate("[document.documentElement.scrollWidth, "
                         "document.documentElement.scrollHeight]")
    assert size[0] <= W and size[1] <= H, f"the page needs scrolling at {W}x{H}: {size}"
    # An LD2410 as well: two tabs switch between the map and the distance plots.
    assert page.is_hidden("#radar-tabs")
    probe.publisher(keys.RADAR_FRAMES, device="7").put(sensor_frame([0] * 9, [0] * 9))
    page.wait_for_selector("#radar-tabs", state="visible", timeout=15_000)
    page.click("#radar-tabs button[data-view='distance']")
    assert page.is_visible("#sensors") and page.is_hidden("#map-box")
    page.click("#radar-tabs button[data-view='map']")
    assert page.is_visible("#map-box") and page.is_hidden("#sensors")
    # Silent: the targets go, the trails fade out.
    page.wait_for_function("window.dash.map.sensors[0].silent "
                           "&& window.dash.map.sensors[0].targets.length === 0", timeout=15_000)
    assert page.errors == []


# --- known people (identity) -----------------------------------------------------------


def test_the_operator_remembers_a_face_sees_the_name_and_forgets_it(
        browser: Any, spawn: Callable[..., Process], probe: Node,
        node_factory: Callable[..., Node]) -> None:
    """Router + eyes driver + controller + dashboard + a stand-in for the identity service's
    queryables: remembering and forgetting need the operator lease; the list and
    the present person's name follow. The screenshot (docs/images/dashboard-identity.png
    is a copy of one) shows the panel with Ada enrolled and present."""
    from ..cli.test_people import FakeIdentity

    identity = FakeIdentity(node_factory("identity"))
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    spawn("eyes")
    spawn("controller")
    expressions.wait_for(timeout=30, what="the controller's own expression")
    port = start_dashboard(spawn)
    page = open_page(browser, port)
    page.wait_for_function("window.dash.known && window.dash.known.known", timeout=20_000)
    assert page.inner_text("#known") == "nobody enrolled"
    page.wait_for_function("window.dash.leases && window.dash.leases.known", timeout=20_000)
    assert page.is_disabled("#enrol")
    # A request sent without control is refused by the server too.
    page.evaluate("send({op: 'enrol', name: 'Eve'})")
    page.wait_for_function(
        "document.getElementById('reply').textContent.startsWith('take control first')",
        timeout=10_000)
    assert identity.requests == []

    page.click("label.switch")
    page.wait_for_function("!document.getElementById('enrol').disabled", timeout=15_000)
    page.fill("#enrol-name", "Ada")
    page.click("#enrol")
    page.wait_for_selector("#known .known-row[data-name='Ada']", timeout=20_000)
    asked = identity.requests[-1]
    assert isinstance(asked, m.EnrolRequest) and asked.name == "Ada"
    assert asked.credential  # the dashboard asks as the operator it is
    assert page.inner_text("#reply") == "remembered Ada (5 samples)"

    # The people service names the person in front: the panel says who is there.
    stamp = m.now_ns()
    people = probe.publisher(keys.PEOPLE_STATE)
    people.put(m.PeopleState(stamp_ns=stamp, people=[m.Person(
        id=3, distance_m=0.9, zone="PERSONAL", seen_by="BOTH", zone_since_ns=stamp,
        arrived_ns=stamp, engagement="ENGAGED", engagement_since_ns=stamp, name="Ada")]))
    page.wait_for_function(
        "document.getElementById('present-names').textContent.includes('person 3 Ada')",
        timeout=15_000)
    page.wait_for_timeout(500)
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "dashboard-identity.png"), full_page=True)
    size = page.evaluate("[document.documentElement.scrollWidth, "
                         "document.documentElement.scrollHeight]")
    assert size[0] <= W and size[1] <= H, f"the page needs scrolling at {W}x{H}: {size}"

    page.click("#known .known-row[data-name='Ada'] button.forget")
    page.wait_for_function("document.getElementById('known').textContent === 'nobody enrolled'",
                           timeout=15_000)
    assert identity.people == {}
    # The list and the reply are two messages to the page: wait for the reply too.
    page.wait_for_function("document.getElementById('reply').textContent === 'forgot Ada'",
                           timeout=15_000)
    assert page.errors == []


# --- many nodes on a laptop screen ------------------------------------------------------

MANY_NODES = ["radar-bridge", "radar-presence", "camera", "face-detector", "controller",
              "people", "eyes", "eye-renderer", "audio", "audio-player", "kitchen-timer", "sim",
              "foxglove", "identity", "ros2-bridge", "greeter", "love_after_10s",
              "wizard_of_oz", "living-room-announcer-with-a-long-name", "doorbell"]
FITS = """() => {
    const W = window.innerWidth, H = window.innerHeight, out = [];
    const scrolls = (el, axis) => {
        const o = getComputedStyle(el)[axis === 'x' ? 'overflowX' : 'overflowY'];
        return o === 'auto' || o === 'scroll';
    };
    for (const panel of document.querySelectorAll('.panel')) {
        const p = panel.getBoundingClientRect();
        const name = panel.querySelector('h2') ? panel.querySelector('h2').textContent : '?';
        if (p.right > W + 1 || p.bottom > H + 1) out.push(`${name}: panel off the page`);
        if (panel.scrollWidth > panel.clientWidth + 1 && !scrolls(panel, 'x'))
            out.push(`${name}: wider than its panel`);
        if (panel.scrollHeight > panel.clientHeight + 1 && !scrolls(panel, 'y'))
            out.push(`${name}: taller than its panel`);
    }
    return out;
}"""
"""What overflows: a panel off the page, or content past a panel that does not scroll."""


def test_twenty_nodes_fit_or_scroll_inside_their_panels(
        browser: Any, spawn: Callable[..., Process], probe: Node) -> None:
    """20 nodes with long messages, two radar sensors: at 1280x800 the page does not
    scroll, every table fits its panel or its panel scrolls, and the last node can be
    scrolled into view inside the Nodes panel. The screenshot is kept for a person to
    look at (docs/images/dashboard-nodes.png is a copy of one)."""
    port = start_dashboard(spawn)
    tokens = [probe.declare_token(probe.key(keys.NODES, node=name, instance=f"{i:032x}"))
              for i, name in enumerate(MANY_NODES, start=1)]
    try:
        page = open_page(browser, port)
        for name in MANY_NODES:
            probe.publisher(keys.DIAGNOSTICS, node=name).put(m.DiagnosticStatus(
                stamp_ns=m.now_ns(), node=name, level="WARN",
                message=f"{name}: no audio hardware (failed to init device, code -401); "
                "playing on the null device (silent)"))
        radar = probe.publisher(keys.RADAR_FRAMES, device="7")
        other = probe.publisher(keys.RADAR_FRAMES, device="8")
        gates = [50] * 9
        radar.put(sensor_frame(gates, gates))
        other.put(sensor_frame(gates, gates, device=8))
        page.wait_for_function(f"""() => (window.dash.nodes || []).filter((n) => n.alive
            && n.level === 'WARN').length >= {len(MANY_NODES)}
            && Object.keys(window.dash.sensors).length >= 2""", timeout=30_000)
        page.wait_for_function(f"document.querySelectorAll('#nodes tbody tr').length >= "
                               f"{len(MANY_NODES)}", timeout=10_000)
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "dashboard-nodes.png"))
        size = page.evaluate("[document.documentElement.scrollWidth, "
                             "document.documentElement.scrollHeight]")
        assert size[0] <= W and size[1] <= H, f"the page needs scrolling at {W}x{H}: {size}"
        assert page.evaluate(FITS) == []
        last = f"#nodes tr[data-node='{sorted(MANY_NODES)[-1]}']"
        seen = page.evaluate(f"""() => {{
            const row = document.querySelector("{last}");
            row.scrollIntoView({{block: 'nearest'}});
            const r = row.getBoundingClientRect();
            const p = document.querySelector('.panel.nodes').getBoundingClientRect();
            return r.top >= p.top && r.bottom <= p.bottom + 1 && r.right <= p.right + 1;
        }}""")
        assert seen, "the last node cannot be scrolled into view inside the Nodes panel"
        # An app that stops leaves the list; a service the config runs stays, down.
        for name in ("doorbell", "camera"):
            tokens[MANY_NODES.index(name)].close()
        page.wait_for_function("""() => {
            const rows = window.dash.nodes || [];
            const camera = rows.find((n) => n.name === 'camera');
            return !rows.some((n) => n.name === 'doorbell') && camera && !camera.alive;
        }""", timeout=60_000)
        assert page.locator("#nodes tr[data-node='doorbell']").count() == 0
        assert page.errors == []
    finally:
        for token in tokens:
            token.close()
