"""The multi-host profile on loopback: TLS, client certificates, access control.

A real `buddybot router` loads deploy/zenoh/router.json5 (certificates from
scripts/make-test-certs.sh); clients use the shipped client files. Hosts are told
apart only by their certificate, as on a real robot. "Nothing arrives" is always
shown after a positive control: an allowed sample sent after the denied one, over
the same path, has arrived, and then a bounded extra wait sees nothing more. The
same holds for liveliness: no host can declare a token for a node it does not run.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import registry
from buddybot.runtime.errors import DuplicateNodeError, ServiceError
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    LOOPBACK,
    Collector,
    Process,
    buddybot_argv,
    free_port,
    retry_until,
)
from tests.deploy.conftest import HOSTS, ZENOH_DIR, HostProfile, TlsRouter, open_client

pytestmark = pytest.mark.integration

QUIET_S = 1.5  # bounded wait after the positive control: a denied sample would be here by now
STAMP = 1_700_000_000_000_000_000
NODES_PREFIX = "buddybot/buddy/nodes"  # liveliness tokens: nodes/<node>/<zid>


def frames(stamp: int) -> m.LD2410TargetDataFrameArray:
    return m.LD2410TargetDataFrameArray(stamp_ns=stamp, device_id=0, sensors=[])


def diagnostics(stamp: int, node: str) -> m.DiagnosticStatus:
    return m.DiagnosticStatus(stamp_ns=stamp, node=node, level="OK", message="test")


# --- who may connect -----------------------------------------------------------------


@pytest.mark.parametrize("host", HOSTS)
def test_host_with_its_certificate_connects(profile: HostProfile, tls_router: TlsRouter,
                                            host: str) -> None:
    session = open_client(tls_router.endpoint, profile.zenoh_file(host))
    try:
        assert str(session.info.zid())
        assert list(session.info.routers_zid()), "connected, but not to the router"
    finally:
        session.close()


def _no_client_certificate(profile: HostProfile) -> str:
    """robot.json5 as a plain TLS client: it trusts the router but shows no certificate."""
    path = profile.work / "anonymous.json5"
    text = Path(profile.zenoh_file("robot")).read_text()
    lines = [ln for ln in text.splitlines() if "connect_private_key" not in ln
             and "connect_certificate" not in ln]
    text = "\n".join(lines).replace("enable_mtls: true", "enable_mtls: false")
    assert "enable_mtls: false" in text
    path.write_text(text)
    return str(path)


def _mismatched_key(profile: HostProfile) -> str:
    """The robot's certificate with another host's private key."""
    path = profile.work / "mismatched.json5"
    text = Path(profile.zenoh_file("robot")).read_text()
    path.write_text(text.replace("/robot.key", "/radar-board.key"))
    return str(path)


def _distrusting_client(profile: HostProfile) -> str:
    """A valid robot certificate, but trusting another CA: the router cannot prove itself."""
    path = profile.work / "distrusting.json5"
    text = Path(profile.zenoh_file("robot")).read_text()
    path.write_text(text.replace("/ca.pem", "/rogue-ca.pem"))
    return str(path)


BAD_CLIENTS: dict[str, Callable[[HostProfile], str | None]] = {
    "no-client-certificate": _no_client_certificate,
    "certificate-from-another-ca": lambda p: p.zenoh_file("robot", cert_name="rogue"),
    "key-does-not-match-certificate": _mismatched_key,
    "client-does-not-trust-the-router": _distrusting_client,
    "plain-tcp": lambda p: None,
}


@pytest.mark.parametrize("case", sorted(BAD_CLIENTS))
def test_client_without_a_valid_certificate_cannot_connect(
    profile: HostProfile, tls_router: TlsRouter, case: str
) -> None:
    zenoh_file = BAD_CLIENTS[case](profile)
    endpoint = tls_router.endpoint
    if zenoh_file is None:
        endpoint = f"tcp/{LOOPBACK}:{tls_router.port}"
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        session = open_client(endpoint, zenoh_file, timeout_ms=3000)
        session.close()
    # The router shrugged it off: still up, and a real host still gets in.
    assert tls_router.process.alive()
    good = open_client(tls_router.endpoint, profile.zenoh_file("robot"))
    good.close()


def test_service_with_a_rogue_certificate_stays_outside(
    host_process: Callable[..., Process], host_node: Callable[..., Node]
) -> None:
    """A real radar bridge whose certificate our CA did not sign keeps waiting for the
    router (it does not crash) and none of its frames arrive; the same service with
    the board's real certificate gets through (the control)."""
    watcher = host_node("operator", "watcher")
    frames = Collector[m.LD2410TargetDataFrameArray](watcher, keys.RADAR_FRAMES, device="*")
    rogue = host_process("radar-board", "run", "radar-bridge", "--sim", "--device-id", "7",
                         cert_name="rogue")
    host_process("radar-board", "run", "radar-bridge", "--sim", "--device-id", "1")
    frames.wait_for(lambda f: f.device_id == 1, timeout=60, what="frames of the real board")
    rogue.wait_for_output("waiting for the Zenoh router", timeout=30)
    with pytest.raises(TimeoutError):
        frames.wait_for(lambda f: f.device_id == 7, timeout=QUIET_S)
    assert rogue.alive(), rogue.output()


# --- who may publish -------------------------------------------------------------------


@dataclass(frozen=True)
class PublishCase:
    """`host` tries `denied`; then `control_host` puts `allowed`, which must arrive."""

    host: str
    node: str
    denied: tuple[keys.Topic, dict[str, str], Callable[[int], Any]]
    allowed: tuple[keys.Topic, dict[str, str], Callable[[int], Any]]
    control_host: str | None = None  # None: the same session (same path, later sample)


PUBLISH_CASES = {
    "radar-board-sets-the-expression": PublishCase(
        "radar-board", "radar-bridge",
        (keys.EXPRESSION, {}, lambda s: m.ScreenExpression(stamp_ns=s, action=3)),
        (keys.RADAR_FRAMES, {"device": "0"}, frames),
    ),
    "radar-board-impersonates-the-controller": PublishCase(
        "radar-board", "radar-bridge",
        (keys.DIAGNOSTICS, {"node": "controller"}, lambda s: diagnostics(s, "controller")),
        (keys.RADAR_FRAMES, {"device": "0"}, frames),
    ),
    "eye-screen-moves-the-eyes": PublishCase(
        "eye-screen", "eye-renderer",
        (keys.EYES_DIRECTION, {}, lambda s: m.EyesDirection(stamp_ns=s, yaw=30.0, pitch=0.0)),
        (keys.DIAGNOSTICS, {"node": "eye-renderer"}, lambda s: diagnostics(s, "eye-renderer")),
    ),
    "camera-host-sets-the-expression": PublishCase(
        "camera-host", "face-detector",
        (keys.EXPRESSION, {}, lambda s: m.ScreenExpression(stamp_ns=s, action=3)),
        (keys.FACE, {"camera": "front"}, lambda s: m.FacePosition(
            stamp_ns=s, frame_id="front", point=m.Point(x=1.0, y=0.0, z=0.0), confidence=0.9)),
    ),
    "camera-host-fakes-radar-frames": PublishCase(
        "camera-host", "camera",
        (keys.RADAR_FRAMES, {"device": "0"}, frames),
        (keys.CAMERA_IMAGE, {"camera": "front"}, lambda s: m.Image(
            stamp_ns=s, frame_id="front", width=2, height=1, encoding="bgr8", data=bytes(6))),
    ),
    "robot-fakes-radar-frames": PublishCase(
        "robot", "controller",
        (keys.RADAR_FRAMES, {"device": "0"}, frames),
        (keys.EXPRESSION, {}, lambda s: m.ScreenExpression(stamp_ns=s, action=0)),
    ),
    "operator-closes-the-lids": PublishCase(
        "operator", "operator",
        (keys.LIDS, {}, lambda s: m.EyeLidControl(stamp_ns=s, eye_id=2, top_lid_position=50,
                                                  bottom_lid_position=50)),
        (keys.LIDS, {}, lambda s: m.EyeLidControl(stamp_ns=s, eye_id=2, top_lid_position=0,
                                                  bottom_lid_position=0)),
        control_host="robot",
    ),
}


@pytest.mark.parametrize("name", sorted(PUBLISH_CASES))
def test_host_cannot_publish_on_a_key_its_acl_does_not_grant(
    host_node: Callable[..., Node], name: str
) -> None:
    case = PUBLISH_CASES[name]
    watcher = host_node("operator", "watcher")  # full read rights
    d_topic, d_params, d_make = case.denied
    a_topic, a_params, a_make = case.allowed
    seen_denied = Collector[Any](watcher, d_topic, **{k: "*" for k in d_params})
    seen_allowed = seen_denied if a_topic is d_topic else Collector[Any](
        watcher, a_topic, **{k: "*" for k in a_params})

    publisher = host_node(case.host, case.node)
    denied_pub = publisher.publisher(d_topic, **d_params)
    control = host_node(case.control_host, "control") if case.control_host else publisher
    allowed_pub = control.publisher(a_topic, **a_params)
    # Fresh stamps: receivers replace a stamp far from the arrival time (limits.py),
    # and the stamp is how the two samples are told apart.
    base = m.now_ns()
    denied_stamp, allowed_stamp = base + 1, base + 2

    def attempt() -> bool:
        # Denied first, then the control: both are repeated until the control shows up
        # (the watcher's subscription may still be on its way to the publisher).
        denied_pub.put(d_make(denied_stamp))
        allowed_pub.put(a_make(allowed_stamp))
        return any(msg.stamp_ns == allowed_stamp for msg in seen_allowed.messages)

    retry_until(attempt, timeout=20, interval=0.2, what=f"{name}: the allowed sample")
    with pytest.raises(TimeoutError):
        seen_denied.wait_for(lambda msg: msg.stamp_ns == denied_stamp, timeout=QUIET_S)
    assert all(msg.stamp_ns != denied_stamp for msg in seen_denied.messages)


def test_denied_publisher_does_not_break_the_host(host_node: Callable[..., Node]) -> None:
    """A denial is silent: the same session keeps publishing what it may."""
    watcher = host_node("operator", "watcher")
    seen = Collector[m.LD2410TargetDataFrameArray](watcher, keys.RADAR_FRAMES, device="*")
    radar = host_node("radar-board", "radar-bridge")
    denied = radar.publisher(keys.EYES_DIRECTION)
    allowed = radar.publisher(keys.RADAR_FRAMES, device="0")
    for i in range(50):
        denied.put(m.EyesDirection(stamp_ns=STAMP + i, yaw=1.0, pitch=1.0))
    retry_until(lambda: allowed.put(frames(STAMP + 99)) or seen.messages, 20, 0.2,
                what="frames after 50 denied puts")


# --- who may read ------------------------------------------------------------------------


def test_eye_screen_reads_the_eyes_and_nothing_else(host_node: Callable[..., Node]) -> None:
    screen = host_node("eye-screen", "eye-renderer")
    screen_eyes = Collector[m.EyesDirection](screen, keys.EYES_DIRECTION)
    screen_frames = Collector[Any](screen, keys.RADAR_FRAMES, device="*")
    screen_faces = Collector[Any](screen, keys.FACE, camera="*")
    watcher = host_node("operator", "watcher")
    watched_frames = Collector[Any](watcher, keys.RADAR_FRAMES, device="*")
    watched_faces = Collector[Any](watcher, keys.FACE, camera="*")

    robot = host_node("robot", "face-detector")
    radar = host_node("radar-board", "radar-bridge")
    face_pub = robot.publisher(keys.FACE, camera="front")
    eyes_pub = robot.publisher(keys.EYES_DIRECTION)
    frames_pub = radar.publisher(keys.RADAR_FRAMES, device="0")
    face = m.FacePosition(stamp_ns=STAMP, frame_id="front", point=m.Point(x=1.0, y=0.0, z=0.0),
                          confidence=0.9)

    def attempt() -> bool:
        face_pub.put(face)
        frames_pub.put(frames(STAMP))
        eyes_pub.put(m.EyesDirection(stamp_ns=STAMP, yaw=5.0, pitch=0.0))
        return bool(screen_eyes.messages and watched_frames.messages and watched_faces.messages)

    retry_until(attempt, timeout=20, interval=0.2, what="eyes at the screen, all at the watcher")
    with pytest.raises(TimeoutError):
        screen_frames.wait_for(timeout=QUIET_S)
    assert not screen_faces.messages and not screen_frames.messages


def test_latched_state_reaches_a_late_eye_screen(host_node: Callable[..., Node]) -> None:
    """History and late-publisher detection run on "@adv" keys: the grants cover them."""
    robot = host_node("robot", "eyes")
    robot.publisher(keys.LIDS).put(
        m.EyeLidControl(stamp_ns=STAMP, eye_id=2, top_lid_position=50, bottom_lid_position=50))
    robot.publisher(keys.EXPRESSION).put(m.ScreenExpression(stamp_ns=STAMP, action=1))

    late = host_node("eye-screen", "eye-renderer")
    lids = Collector[m.EyeLidControl](late, keys.LIDS)
    expression = Collector[m.ScreenExpression](late, keys.EXPRESSION)
    assert lids.wait_for(timeout=20, what="latched lids").top_lid_position == 50
    assert expression.wait_for(timeout=20, what="latched expression").action == 1


def test_only_the_robot_calls_its_services(host_node: Callable[..., Node]) -> None:
    player = host_node("robot", "audio-player")
    calls: list[str] = []

    def stop(_req: m.Trigger) -> m.TriggerReply:
        calls.append("stop")
        return m.TriggerReply(success=True, message="stopped")

    player.serve(keys.AUDIO_STOP, stop)
    controller = host_node("robot", "controller")
    reply = retry_until(lambda: controller.call(keys.AUDIO_STOP, m.Trigger(), timeout=2), 20,
                        0.2, "robot calling its own player")
    assert reply.success
    count = len(calls)
    for host in ("operator", "eye-screen", "radar-board"):
        intruder = host_node(host, f"intruder-{host}")
        with pytest.raises(ServiceError, match="no reply"):
            intruder.call(keys.AUDIO_STOP, m.Trigger(), timeout=2)
    assert len(calls) == count, "a denied query reached the player"


# --- real processes, configured like the hosts ------------------------------------------


def test_radar_board_and_robot_services_work_through_the_profile(
    host_process: Callable[..., Process], host_node: Callable[..., Node]
) -> None:
    """radar-bridge (--sim) as the radar board, radar-presence as the robot computer,
    each `buddybot run` with a TOML naming its Zenoh file: presence reaches the operator."""
    watcher = host_node("operator", "watcher")
    seen_frames = Collector[m.LD2410TargetDataFrameArray](watcher, keys.RADAR_FRAMES, device="*")
    presence = Collector[m.PresenceDetection](watcher, keys.PRESENCE)
    host_process("radar-board", "run", "radar-bridge", "--sim")
    host_process("robot", "run", "radar-presence")
    seen_frames.wait_for(timeout=60, what="simulated radar frames from the radar board")
    got = presence.wait_for(lambda p: p.presence_state == m.PresenceState.IN_RANGE, timeout=60,
                            what="presence from the robot computer")
    assert got.distance_m < 2.0
    # `buddybot nodes` from the operator's laptop sees both hosts' services.
    listing = host_process("operator", "nodes")
    assert listing.proc.wait(60) == 0, listing.output()
    names = listing.output().split()
    assert "radar-bridge" in names and "radar-presence" in names, listing.output()


def test_buddybot_pub_as_the_wrong_host_is_dropped(
    host_process: Callable[..., Process], host_node: Callable[..., Node]
) -> None:
    """The CLI as each host would run it: only the allowed publish arrives."""
    watcher = host_node("operator", "watcher")
    expression = Collector[m.ScreenExpression](watcher, keys.EXPRESSION)
    denied = host_process("radar-board", "pub", "eyes/expression",
                          msgspec.json.encode({"stamp_ns": STAMP + 1, "action": 3}).decode(),
                          "--rate", "20")
    allowed = host_process("robot", "pub", "eyes/expression",
                           msgspec.json.encode({"stamp_ns": STAMP + 2, "action": 0}).decode(),
                           "--rate", "20")
    expression.wait_for(lambda x: x.stamp_ns == STAMP + 2, timeout=30, what="robot's expression")
    with pytest.raises(TimeoutError):
        expression.wait_for(lambda x: x.stamp_ns == STAMP + 1, timeout=QUIET_S)
    assert denied.alive() and allowed.alive(), "a denial must not kill the publisher"


def test_remote_eye_screen_renders_what_the_robot_sends(
    host_process: Callable[..., Process], host_node: Callable[..., Node]
) -> None:
    """eye-renderer as the eye screen: the robot's latched lids and its gaze reach the
    renderer through the router, and the renderer's diagnostics reach the operator."""
    watcher = host_node("operator", "watcher")
    health = Collector[m.DiagnosticStatus](watcher, keys.DIAGNOSTICS, node="eye-renderer")
    robot = host_node("robot", "eyes")
    robot.publisher(keys.LIDS).put(
        m.EyeLidControl(stamp_ns=STAMP, eye_id=2, top_lid_position=0, bottom_lid_position=0))
    gaze = robot.publisher(keys.EYES_DIRECTION)
    renderer = host_process("eye-screen", "run", "eye-renderer", "--no-browser",
                            "--port", str(free_port()))
    renderer.wait_for_output("eye renderer serving", timeout=60)

    def forwarded() -> bool:
        gaze.put(m.EyesDirection(stamp_ns=STAMP, yaw=10.0, pitch=0.0))
        return any(int(d.values.get("messages", 0)) >= 2 for d in health.messages)

    retry_until(forwarded, timeout=60, interval=0.5, what="renderer counting eye messages")
    assert renderer.alive()


def test_camera_host_services_work_through_the_profile(
    host_process: Callable[..., Process], host_node: Callable[..., Node]
) -> None:
    """camera (--sim) and face-detector as the camera host: the robot computer gets
    frames and faces, the operator sees both services alive, and the detector's
    debug image flows only while someone watches it (matching status through the ACL)."""
    robot = host_node("robot", "controller")
    faces = Collector[m.FacePosition](robot, keys.FACE, camera="front")
    host_process("camera-host", "run", "camera", "--sim", "--fps", "5", "--encoding", "jpeg")
    host_process("camera-host", "run", "face-detector")
    got = faces.wait_for(timeout=180, what="faces from the camera host")
    assert 0.0 < got.confidence <= 1.0
    watcher = host_node("operator", "watcher")
    debug = Collector[m.Image](watcher, keys.DEBUG_IMAGE, camera="front")
    debug.wait_for(timeout=180, what="the debug image, once watched")  # as long as faces
    alive = retry_until(lambda: {n for n in ("camera", "face-detector") if watcher.live_instances(
        f"{NODES_PREFIX}/{n}/*", timeout=1.0)} == {"camera", "face-detector"},
        30, 0.5, what="camera and face-detector tokens at the operator")
    assert alive


# --- a broken router profile -------------------------------------------------------------


def _router_exit(zenoh_file: str, tmp_path: Path) -> tuple[int, str]:
    port = free_port()
    proc = Process(buddybot_argv("router", "--listen", f"tls/{LOOPBACK}:{port}",
                                 "--zenoh-config", zenoh_file), f"bad-router-{port}",
                   tmp_path / "logs")
    try:
        code = proc.proc.wait(60)
    finally:
        proc.stop()
    return code, proc.output()


def test_router_with_a_mangled_profile_is_a_config_error(profile: HostProfile,
                                                         tmp_path: Path) -> None:
    """Exit status 2 (systemd does not restart on it) and the file named."""
    text = Path(profile.zenoh_file("router")).read_text()
    broken = tmp_path / "router-broken.json5"
    broken.write_text(text[: len(text) // 2])
    code, output = _router_exit(str(broken), tmp_path)
    assert code == 2, output
    assert "config error" in output and "router-broken.json5" in output


def test_router_without_its_key_says_which_file(profile: HostProfile, tmp_path: Path) -> None:
    text = Path(profile.zenoh_file("router")).read_text()
    missing = tmp_path / "router-nokey.json5"
    missing.write_text(text.replace("/router.key", "/no-such.key"))
    code, output = _router_exit(str(missing), tmp_path)
    assert code != 0, output
    assert "private key" in output


# --- who may say a node is alive ------------------------------------------------------


@dataclass(frozen=True)
class TokenCase:
    """`host` declares a token for `own` (allowed: the control) and for `fake`."""

    host: str
    own: str | None  # None: the host runs no node (operator); the robot is the control
    fake: str


TOKEN_CASES = {
    "radar-board-fakes-the-controller": TokenCase("radar-board", "radar-bridge", "controller"),
    "eye-screen-fakes-the-eyes-driver": TokenCase("eye-screen", "eye-renderer", "eyes"),
    "camera-host-fakes-the-radar-bridge": TokenCase("camera-host", "camera", "radar-bridge"),
    "camera-host-fakes-the-eye-renderer": TokenCase("camera-host", "face-detector",
                                                    "eye-renderer"),
    "robot-fakes-the-radar-bridge": TokenCase("robot", "controller", "radar-bridge"),
    "operator-fakes-the-audio-player": TokenCase("operator", None, "audio-player"),
    "radar-board-declares-a-wildcard-node": TokenCase("radar-board", "radar-bridge", "*"),
}


def test_liveliness_grants_name_the_nodes_of_each_host() -> None:
    """Static: every `liveliness_token` grant under nodes/ is one node name's subtree,
    never nodes/** (which would let the host fake any service)."""
    acl = json.loads(zenoh.Config.from_file(str(ZENOH_DIR / "router.json5"))
                     .get_json("access_control"))
    services = {e.name for e in registry.SERVICES if not e.simulation}  # a deployed robot
    granted: dict[str, set[str]] = {}
    rules = {r["id"]: r for r in acl["rules"]}
    for policy in acl["policies"]:
        for rid in policy["rules"]:
            rule = rules[rid]
            if "ingress" not in rule["flows"] or "liveliness_token" not in rule["messages"]:
                continue
            for key in rule["key_exprs"]:
                if key.startswith(f"{NODES_PREFIX}/"):
                    node = key[len(NODES_PREFIX) + 1:]
                    assert node.endswith("/**") and node[:-3] in services, f"{rid}: {key}"
                    for subject in policy["subjects"]:
                        granted.setdefault(subject, set()).add(node[:-3])
                else:
                    assert "/nodes" not in key and not key.endswith("buddy/**"), f"{rid}: {key}"
    assert granted["radar-board"] == {"radar-bridge"}
    assert granted["eye-screen"] == {"eye-renderer"}
    assert granted["camera-host"] == {"camera", "face-detector"}
    assert granted["robot"] == services - {"radar-bridge"}
    assert "operator" not in granted


class TokenWatch:
    """Liveliness tokens under nodes/** as a full-read host sees them (puts only).

    With history: on a busy machine the router can take a token declared by
    another session before it has this subscription, and a subscriber without
    history would never hear of it."""

    def __init__(self, session: zenoh.Session) -> None:
        self.keys: list[str] = []
        self._sub = session.liveliness().declare_subscriber(f"{NODES_PREFIX}/**", self._on,
                                                            history=True)

    def _on(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.keys.append(str(sample.key_expr))


@pytest.mark.parametrize("name", sorted(TOKEN_CASES))
def test_host_declares_liveliness_only_for_the_nodes_it_runs(
    profile: HostProfile, tls_router: TlsRouter, name: str
) -> None:
    """No host can make another host's service look alive: its token for a foreign
    node name never reaches a watcher (neither as a live token nor in a liveliness
    query), while its token for its own node, declared after it, does."""
    case = TOKEN_CASES[name]
    sessions: list[zenoh.Session] = []
    try:
        watcher = open_client(tls_router.endpoint, profile.zenoh_file("operator"))
        sessions.append(watcher)
        seen = TokenWatch(watcher)
        host = open_client(tls_router.endpoint, profile.zenoh_file(case.host))
        sessions.append(host)
        zid = str(host.info.zid())
        fake_key = f"{NODES_PREFIX}/{case.fake}/{zid}"
        fake = host.liveliness().declare_token(fake_key)
        if case.own is not None:
            control_key = f"{NODES_PREFIX}/{case.own}/{zid}"
            control_session = host  # the same session and path, declared later
        else:
            control_session = open_client(tls_router.endpoint, profile.zenoh_file("robot"))
            sessions.append(control_session)
            control_key = f"{NODES_PREFIX}/controller/{control_session.info.zid()}"
        control = control_session.liveliness().declare_token(control_key)
        retry_until(lambda: control_key in seen.keys, 60, 0.1,
                    what=f"{name}: the allowed token at the watcher")

        def answered() -> set[str] | None:
            """The tokens a liveliness query finds, once it finds the allowed one
            (on a busy machine one query can end before the router answered)."""
            replies = watcher.liveliness().get(f"{NODES_PREFIX}/**", timeout=QUIET_S)
            found = {str(r.ok.key_expr) for r in replies if r.ok is not None}
            return found if control_key in found else None

        queried = retry_until(answered, 60, 0.1, what=f"{name}: the allowed token queried")
        with pytest.raises(TimeoutError):
            retry_until(lambda: fake_key in seen.keys, QUIET_S, 0.1, what="the faked token")
        assert fake_key not in queried, f"{fake_key} answered a liveliness query"
        assert all(not k.startswith(f"{NODES_PREFIX}/{case.fake}/") or case.fake == case.own
                   for k in seen.keys), seen.keys
        fake.undeclare()
        control.undeclare()
    finally:
        for session in reversed(sessions):
            session.close()


def test_duplicate_service_is_seen_through_the_acl(
    profile: HostProfile, tls_router: TlsRouter, host_node: Callable[..., Node]
) -> None:
    """A host may watch and query its own node name: a second radar bridge on the
    radar board is refused (the first one's token reached it), so the ACL that stops
    fakes does not blind a host to a copy of itself."""
    first = host_node("radar-board", "radar-bridge")
    watcher = host_node("operator", "watcher")
    retry_until(lambda: first.instance in watcher.live_instances(
        f"{NODES_PREFIX}/radar-bridge/*", timeout=1.0), 20, 0.2,
        what="the first radar bridge's token at the operator")
    second: Node | None = None
    try:
        with pytest.raises(DuplicateNodeError, match="already running"):
            second = Node("radar-bridge", connect=[tls_router.endpoint],
                          zenoh_config_file=profile.zenoh_file("radar-board"), unique=True)
    finally:
        if second is not None:
            second.close()


# --- the ROS 2 bridge's keys --------------------------------------------------------------

ROS_KEY = "0/face_position/geometry_msgs::msg::dds_::PointStamped_/RIHS01_" + "4c" * 32
ROS_LATCHED = "0/eye_lid_control/buddybot_interfaces::msg::dds_::EyeLidControl_/RIHS01_" + "1d" * 32


def _ros_token(session: zenoh.Session, node: str) -> str:
    return f"@ros2_lv/0/{session.info.zid()}/0/0/NN/%/%/{node}"


def test_ros_2_keys_cross_the_acl_on_the_robot_computer_only(
    profile: HostProfile, tls_router: TlsRouter
) -> None:
    """The bridge (robot certificate) and a ROS 2 node on the robot computer meet
    through the router: data keys of domain 0, the graph's tokens, and a
    transient-local value fetched late through the "@adv" grants. The radar
    board's put and token on the same keys never arrive (after the control)."""
    sessions: list[zenoh.Session] = []
    try:
        bridge = open_client(tls_router.endpoint, profile.zenoh_file("robot"))
        ros_node = open_client(tls_router.endpoint, profile.zenoh_file("robot"))
        intruder = open_client(tls_router.endpoint, profile.zenoh_file("radar-board"))
        sessions += [bridge, ros_node, intruder]
        samples: list[bytes] = []
        tokens: list[str] = []
        ros_node.declare_subscriber("0/**", lambda s: samples.append(s.payload.to_bytes()))
        ros_node.liveliness().declare_subscriber(
            "@ros2_lv/0/**", lambda s: tokens.append(str(s.key_expr)), history=True)
        latched = zenoh.ext.declare_advanced_publisher(
            bridge, ROS_LATCHED, cache=zenoh.ext.CacheConfig(max_samples=1),
            publisher_detection=True,
            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=None,
                                                                sporadic_heartbeat=0.5))
        latched.put(b"lids")
        intruder_token = intruder.liveliness().declare_token(_ros_token(intruder, "fake"))
        bridge_token = bridge.liveliness().declare_token(_ros_token(bridge, "buddybot_bridge"))

        def attempt() -> bool:
            intruder.put(ROS_KEY, b"denied")
            bridge.put(ROS_KEY, b"allowed")
            return b"allowed" in samples

        retry_until(attempt, 20, 0.2, what="the bridge's sample at the ROS 2 node")
        retry_until(lambda: _ros_token(bridge, "buddybot_bridge") in tokens, 20, 0.1,
                    what="the bridge's graph token")
        history: list[bytes] = []
        late = zenoh.ext.declare_advanced_subscriber(
            ros_node, ROS_LATCHED, lambda s: history.append(s.payload.to_bytes()),
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
        retry_until(lambda: b"lids" in history, 20, 0.1, what="the latched value, late")
        with pytest.raises(TimeoutError):
            retry_until(lambda: b"denied" in samples or _ros_token(intruder, "fake") in tokens,
                        QUIET_S, 0.1, what="the radar board's ROS 2 put or token")
        late.undeclare()
        latched.undeclare()
        intruder_token.undeclare()
        bridge_token.undeclare()
    finally:
        for session in reversed(sessions):
            session.close()
