"""`buddybot run foxglove` (services/foxglove/service.py): the URLs it prints (pure), and
the bridge as a real process between a real router and a Foxglove WebSocket client.

The client speaks the Foxglove protocol itself (`ws_client.py`), as the
app does: it reads the advertised channels, subscribes, and decodes the
binary message frames; a probe node publishes what it should receive.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import subprocess
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import msgspec
import numpy as np
import pytest

from buddybot.contract import channels, keys
from buddybot.contract import messages as m
from buddybot.foxglove.service import urls
from buddybot.runtime import leasing
from buddybot.runtime.node import Node
from buddybot.tools import testing as attack
from buddybot.tools.testing import Collector, Process, buddybot_argv, free_port, retry_until

from .ws_client import CallFailed, FoxgloveClient

PREFIX = "buddybot/buddy"
PRESENCE = f"{PREFIX}/radar/presence"
FACES = f"{PREFIX}/camera/front/faces"
ANNOTATIONS = f"{FACES}/annotations"
IMAGE = f"{PREFIX}/camera/front/image"
FPS_LIMIT = 5.0


def presence(distance: float) -> m.PresenceDetection:
    return m.PresenceDetection(stamp_ns=m.now_ns(), target_state=m.PresenceTarget.STANDING,
                               presence_state=m.PresenceState.IN_RANGE, distance_m=distance)


def faces() -> m.FaceDetections:
    box = m.FaceBox(x0=10.0, y0=20.0, x1=50.0, y1=70.0, score=0.9, followed=True,
                    keypoints=[m.PixelPoint(x=20.0, y=30.0)])
    return m.FaceDetections(stamp_ns=m.now_ns(), frame_id="front", width=64, height=48,
                            faces=[box])


def pattern() -> np.ndarray:
    """A smooth 64x48 BGR test picture (JPEG keeps it close)."""
    y, x = np.mgrid[0:48, 0:64]
    return np.stack([x * 4, y * 5, np.full_like(x, 128)], axis=-1).astype(np.uint8)


class ImageSource:
    """Raw `bgr8` frames on camera/front/image at 20 Hz from the probe, in a thread."""

    def __init__(self, node: Node) -> None:
        self.pub = node.publisher(keys.CAMERA_IMAGE, camera="front")
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        data = pattern().tobytes()
        while not self.stop.wait(0.05):
            self.pub.put(m.Image(stamp_ns=m.now_ns(), frame_id="front", width=64, height=48,
                                 encoding="bgr8", data=data))

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)


def start_bridge(spawn: Callable[..., Process], tmp_path: Path, idle_s: float = 600.0) -> int:
    """The bridge on a free port; its expression lease given back after `idle_s`."""
    port = free_port()
    config = tmp_path / "foxglove.toml"
    config.write_text(f"[foxglove]\nlease_idle_s = {idle_s}\n")
    proc = spawn("foxglove", "--port", str(port), "--max-image-fps", str(FPS_LIMIT),
                 "--config", str(config))
    proc.wait_for_output("foxglove bridge serving", timeout=30)
    return port


@pytest.fixture
def bridge(spawn: Callable[..., Process], tmp_path: Path) -> Iterator[int]:
    yield start_bridge(spawn, tmp_path)


ORIGIN_CASES = [
    (None, "http://evil.example", 403),          # any web page: refused
    (None, "null", 403),
    (None, "https://app.foxglove.dev.evil.example", 403),
    ("attacker.example", None, 421),              # a name the bridge is not served at
    ("evil.test", "http://evil.test", 421),       # DNS rebinding
    (None, "https://app.foxglove.dev", 101),     # the Foxglove web app
    (None, "file://", 101),                       # the desktop app
    (None, "http://localhost:5173", 101),         # a page from this machine's loopback
    (None, None, 101),                            # a program, not a page
]


@pytest.mark.integration
def test_only_the_foxglove_app_and_this_machine_may_connect(bridge: int) -> None:
    got = [(host, origin, attack.http_status(bridge, "/", origin=origin, websocket=True,
                                      host=None if host is None else f"{host}:{bridge}"))
           for host, origin, _status in ORIGIN_CASES]
    assert got == ORIGIN_CASES


@pytest.mark.integration
def test_a_descriptor_flood_leaves_the_bridge_serving_and_healthy(
        spawn: Callable[..., Process], probe: Node) -> None:
    """300 held sockets under a 256-descriptor limit: the SDK's own listener
    would lose its accept loop for good; the gate cuts the oldest unfinished
    ones, a real client still connects and the diagnostics stay OK."""
    port = free_port()
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="foxglove")
    proc = spawn("foxglove", "--port", str(port), nofile=256)
    proc.wait_for_output("foxglove bridge serving", timeout=30)
    flood = attack.HeldSockets(port, 300)
    try:
        async def connect() -> dict[str, object]:
            client = await FoxgloveClient.connect(port)
            await client.close()
            return client.server_info

        info = asyncio.run(connect())
    finally:
        flood.close()
    assert info.get("name") == "buddybot"
    status = diag.wait_for(lambda s: int(s.values.get("connections_evicted", 0)) > 0,
                           timeout=20, what="the gate's counters")
    assert status.level == "OK", status
    assert proc.alive() and "Traceback" not in proc.output()


def bridge_subscribes(probe: Node, key: str) -> bool:
    info: m.NodeInfo = probe.call(keys.NODE_INFO, m.Trigger(), node="foxglove", timeout=5)
    return key in info.subscriptions


async def until_received(client: FoxgloveClient, sub_id: int, publish: Callable[[], None],
                         timeout: float = 20.0) -> bytes:
    """Publish until the subscription delivers (the subscribe reaches the server
    asynchronously, and only subscribed channels are sent); the first payload."""
    got: list[tuple[int, bytes]] = []

    def arrived() -> bool:
        got.extend(client.take(sub_id))
        return bool(got)

    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not arrived():
        if loop.time() > end:
            raise TimeoutError(f"nothing on subscription {sub_id} within {timeout} s")
        publish()
        await client.pump(0.3)
    return got[0][1]


@pytest.mark.integration
def test_keys_annotations_images_and_services_reach_a_foxglove_client(
        bridge: int, probe: Node) -> None:
    presence_pub = probe.publisher(keys.PRESENCE)
    faces_pub = probe.publisher(keys.FACES, camera="front")
    presence_pub.put(presence(1.5))  # latched: the bridge sees it whenever it subscribes
    diagnostics = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="foxglove")
    garbage = probe.raw_publisher(f"{PREFIX}/radar/presence", "application/json")
    probe.serve(keys.PLAY_SOUND, lambda goal: m.PlaySoundReply(
        goal_id="g1", accepted=goal.sound == "hello", message=f"playing {goal.sound}"))

    async def scenario() -> None:
        client = await FoxgloveClient.connect(bridge)
        try:
            assert client.server_info["name"] == "buddybot"
            assert "services" in client.server_info["capabilities"]

            # A key becomes a channel (its full key) with its JSON Schema when first seen.
            channel = await client.channel(PRESENCE)
            assert channel["encoding"] == "json"
            assert channel["schemaName"] == "buddybot.PresenceDetection"
            assert channel["schemaEncoding"] == "jsonschema"
            assert json.loads(channel["schema"])["title"] == "PresenceDetection"

            await client.subscribe(1, PRESENCE)
            # A bad payload is counted by the bridge's node and never shown...
            garbage.put(b'{"distance_m": "far"}')
            diagnostics.wait_for(lambda d: int(d.values.get("malformed", 0)) >= 1, 20,
                                 "the bridge counting the malformed sample")
            await client.pump(0.5)
            assert client.take(1) == []
            # ...and what follows still arrives.
            sent = presence(0.87)
            payload = await until_received(client, 1, lambda: presence_pub.put(sent))
            assert msgspec.json.decode(payload, type=m.PresenceDetection) == sent

            # Faces also become ImageAnnotations (boxes over the image).
            det = faces()
            await until_received_channel(client, ANNOTATIONS, lambda: faces_pub.put(det))
            ann_channel = client.channels[ANNOTATIONS]
            assert ann_channel["schemaName"] == "foxglove.ImageAnnotations"
            await client.subscribe(2, ANNOTATIONS)
            payload = await until_received(client, 2, lambda: faces_pub.put(det))
            drawn = json.loads(payload)
            assert drawn == json.loads(msgspec.json.encode(channels.annotations(det)))
            box = drawn["points"][0]["points"]
            assert box == [{"x": 10.0, "y": 20.0}, {"x": 50.0, "y": 20.0},
                           {"x": 50.0, "y": 70.0}, {"x": 10.0, "y": 70.0}]

            # The bridge's services: a bad expression is refused by name (the lease
            # path: test_a_client_expression_goes_through_an_operator_lease), the
            # play_sound action is queried.
            with pytest.raises(CallFailed, match="action"):
                await client.call("eyes/expression", b'{"action": "EYE_NOPE"}', 2)
            reply = await client.call("audio/play_sound", b'{"sound": "hello"}', 3)
            assert msgspec.json.decode(reply, type=m.PlaySoundReply) == m.PlaySoundReply(
                goal_id="g1", accepted=True, message="playing hello")
        finally:
            await client.close()

    asyncio.run(scenario())


@pytest.mark.integration
def test_a_quiet_client_gives_the_expression_back(
        spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> None:
    """A Foxglove window that set one expression used to hold the eyes until someone
    released them; now the lease ends `lease_idle_s` after the last call."""
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    leases = Collector[m.Leases](probe, keys.LEASES)
    spawn("eyes")
    spawn("controller")
    own = expressions.wait_for(timeout=30, what="the controller's own expression").action
    port = start_bridge(spawn, tmp_path, idle_s=1.0)

    async def scenario() -> None:
        client = await FoxgloveClient.connect(port)
        try:
            await client.call("eyes/expression", b'{"action": "ANIMATE_LOVE"}', 1)
        finally:
            await client.close()

    asyncio.run(scenario())
    expressions.wait_for(lambda e: e.action == m.ExpressionAction.ANIMATE_LOVE, 30, "LOVE")
    expressions.clear()
    leases.wait_for(lambda s: any(e.holder == "foxglove" and "no Foxglove call" in e.message
                                  for e in s.ended), 30, "the idle lease given back")
    expressions.wait_for(lambda e: e.action == own, 30, f"the robot's own {own.name} back")


@pytest.mark.integration
def test_a_client_expression_goes_through_an_operator_lease(
        bridge: int, probe: Node, spawn: Callable[..., Process],
        node_factory: Callable[..., Node], state_dir: Path) -> None:
    """The bridge never publishes eyes/expression: it takes an operator lease on
    `expression` and asks the arbiter (eyes/command); eyes/release gives the
    expression back; another operator's lease refuses it with the holder named."""
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    leases = Collector[m.Leases](probe, keys.LEASES)
    spawn("eyes")
    spawn("controller")
    own = expressions.wait_for(timeout=30, what="the controller's own expression").action
    retry_until(lambda: any(i.node == "eyes" and "eyes/command" in i.services
                            for i in probe.node_infos(1.0)),
                30, 0.2, "the arbiter's lease services")

    async def scenario() -> None:
        client = await FoxgloveClient.connect(bridge)
        try:
            reply = await client.call("eyes/expression", b'{"action": "EYE_GRIN"}', 1)
            assert msgspec.json.decode(reply, type=m.ScreenExpression).action == \
                m.ExpressionAction.EYE_GRIN
            expressions.wait_for(lambda e: e.action == m.ExpressionAction.EYE_GRIN, 10,
                                 "EYE_GRIN from the controller")
            held = leases.wait_for(lambda s: any(x.holder == "foxglove" for x in s.leases),
                                   10, "the bridge's lease").leases
            assert [(x.priority, x.resources) for x in held] == [("operator", ["expression"])]
            await client.call("eyes/expression", b'{"action": "EYE_SAD"}', 2)  # same lease
            expressions.wait_for(lambda e: e.action == m.ExpressionAction.EYE_SAD, 10)
            assert [x.holder for x in leases.messages[-1].leases] == ["foxglove"]
            expressions.clear()
            released = await client.call("eyes/release", b"{}", 3)
            assert msgspec.json.decode(released, type=m.TriggerReply).success
            expressions.wait_for(lambda e: e.action == own, 10, "the controller's own again")

            wizard = node_factory("wizard")
            taken = leasing.ask(wizard, m.LeaseRequest(
                holder="wizard", instance=wizard.instance, resources=["expression"],
                priority="operator", credential=leasing.operator_credential(state_dir)),
                timeout=10)
            assert taken.granted, taken
            with pytest.raises(CallFailed, match="held by wizard"):
                await client.call("eyes/expression", b'{"action": "EYE_GRIN"}', 4)
        finally:
            await client.close()

    asyncio.run(scenario())
    # The refused call showed nothing (the list was cleared before the release).
    assert m.ExpressionAction.EYE_GRIN not in [e.action for e in expressions.messages]


async def until_received_channel(client: FoxgloveClient, topic: str,
                                 publish: Callable[[], None], timeout: float = 20.0) -> None:
    """Publish until `topic` is advertised (a non-latched key is seen only when sent)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while topic not in client.channels:
        if loop.time() > end:
            raise TimeoutError(f"{topic} not advertised within {timeout} s")
        publish()
        await client.pump(0.3)


@pytest.mark.integration
def test_images_are_compressed_rate_limited_and_pulled_only_while_watched(
        bridge: int, probe: Node) -> None:
    source = ImageSource(probe)

    async def scenario() -> None:
        client = await FoxgloveClient.connect(bridge)
        try:
            # Found from the camera's own report, advertised before anyone watches...
            channel = await client.channel(IMAGE, timeout=30)
            assert channel["schemaName"] == "foxglove.CompressedImage"
            # ...and not pulled over the bus while nobody does.
            assert not bridge_subscribes(probe, IMAGE[len(PREFIX) + 1:])

            await client.subscribe(5, IMAGE)
            await client.until(lambda: any(s == 5 for s, _t, _p in client.messages), 20,
                               "a first image")
            image = json.loads(client.take(5)[0][1])
            assert image["format"] == "jpeg" and image["frame_id"] == "front"
            jpeg = base64.b64decode(image["data"])
            pixels = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
            assert pixels.shape == (48, 64, 3)
            assert np.abs(pixels.astype(int) - pattern().astype(int)).mean() < 8
            assert bridge_subscribes(probe, IMAGE[len(PREFIX) + 1:])

            # 20 Hz in, at most FPS_LIMIT out.
            await client.pump(3.0)
            count = len(client.take(5))
            assert 3 <= count <= FPS_LIMIT * 3 + 2, count

            # A live parameter change applies at once (no restart).
            reply: m.ParamReply = probe.call(
                keys.PARAMS, m.ParamRequest(op="set", values={"max_image_fps": 1.0}),
                node="foxglove", timeout=5)
            assert reply.changed == ["max_image_fps"], reply
            client.take(5)
            await client.pump(4.0)
            count = len(client.take(5))
            assert 1 <= count <= 6, count

            await client.unsubscribe(5)
            retry_until(lambda: not bridge_subscribes(probe, IMAGE[len(PREFIX) + 1:]), 15,
                        what="the bridge dropping the image subscription")
        finally:
            await client.close()

    try:
        asyncio.run(scenario())
    finally:
        source.close()


@pytest.mark.integration
def test_a_busy_port_exits_1_with_one_line(endpoint: str) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run(
            buddybot_argv("foxglove", "--port", str(port), "--connect", endpoint),
            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    # The holder is this test's process: named with its pid.
    assert lines[0].startswith(f"buddybot foxglove: cannot serve on 127.0.0.1:{port}: the "
                               "port is taken by ")
    assert f"pid {os.getpid()} (Address already in use)" in lines[0]


def test_urls_name_a_reachable_host_and_open_the_app_on_it() -> None:
    ws, app = urls("0.0.0.0", 8765)
    assert ws == "ws://127.0.0.1:8765"
    assert app == ("https://app.foxglove.dev/?ds=foxglove-websocket"
                   "&ds.url=ws%3A%2F%2F127.0.0.1%3A8765")
    assert urls("buddy.local", 9000)[0] == "ws://buddy.local:9000"
