"""`buddybot bag`: the verb's own parts, and as processes on a real router: record,
info, play and their failures."""

from __future__ import annotations

import json
import resource
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.cli import bag as bag_cli
from buddybot.contract import channels, keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node
from buddybot.tools import bag, bag_recover, mcap_records
from buddybot.tools.testing import InProcessRouter, Process, buddybot_argv, retry_until
from tests.tools.mcap_bomb import write_bomb
from tests.tools.test_bag import concrete_key, samples, write_recording


def test_info_counts_and_rates(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    key = concrete_key(keys.PUPIL)
    payload = keys.PUPIL.codec.encode(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=5))
    base = time.time_ns()
    write_recording(tmp_path / "r.mcap", [(key, payload, base + i * 100_000_000)
                                          for i in range(21)])
    info = bag.read_info(tmp_path / "r.mcap")
    assert info.duration_s == pytest.approx(2.0)
    (channel,) = info.channels
    assert channel.count == 21 and channel.rate_hz(info.duration_s) == pytest.approx(10.5)
    assert bag_cli.print_info(str(tmp_path / "r.mcap"), as_json=True) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["channels"][0]["key"] == key and shown["messages"] == 21
    assert bag_cli.print_info(str(tmp_path / "r.mcap"), as_json=False) == 0
    text = capsys.readouterr().out
    assert "Duration:   2.000 s" in text and key in text and "10.50 Hz" in text


def test_record_keys_defaults_images_and_errors() -> None:
    default = dict(bag_cli.record_keys("buddy", [], images=False))
    assert "buddybot/buddy/camera/*/image" not in default
    assert "buddybot/buddy/camera/*/debug_image" not in default
    assert default["buddybot/buddy/radar/presence"] is True  # latched: with history
    assert default["buddybot/buddy/radar/*/frames"] is False
    assert len(default) == len(keys.TOPICS) - 2
    with_images = dict(bag_cli.record_keys("buddy", [], images=True))
    assert "buddybot/buddy/camera/*/image" in with_images
    chosen = bag_cli.record_keys("buddy", ["radar/**", "eyes/expression"], images=False)
    assert chosen == [("buddybot/buddy/radar/**", True),
                      ("buddybot/buddy/eyes/expression", True)]
    with pytest.raises(UsageError, match="no/such: matches no topic"):
        bag_cli.record_keys("buddy", ["no/such"], images=False)
    with pytest.raises(UsageError, match="audio/play_sound: matches no topic"):
        bag_cli.record_keys("buddy", ["audio/play_sound"], images=False)  # a service


class RawCollector:
    """Every sample on `buddybot/**` with its arrival time (monotonic)."""

    def __init__(self, node: Node, key: str = "buddybot/**",
                 latched: frozenset[str] = frozenset()) -> None:
        self.items: list[tuple[str, bytes, float]] = []
        self._lock = threading.Lock()
        self._latched = latched
        node.subscribe_raw(key, self._on)
        for each in latched:
            node.subscribe_raw(each, self._on_latched, recover=True)

    def _on(self, key: str, payload: bytes, _encoding: str) -> None:
        if key not in self._latched:
            self._on_latched(key, payload, _encoding)

    def _on_latched(self, key: str, payload: bytes, _encoding: str) -> None:
        """`latched` keys come through their own subscription as a service
        subscribes to them: history, and recovery from the heartbeat. Their QoS
        drops under congestion (on a busy machine the player's puts leave back
        to back, express, and their priority's queue holds two); a history-only
        probe asked the player's cache when it appeared, still empty, so the
        value was lost for it, where a service fetches it again."""
        with self._lock:
            self.items.append((key, payload, time.monotonic()))

    def on(self, key: str) -> list[tuple[bytes, float]]:
        with self._lock:
            return [(p, t) for k, p, t in self.items if k == key]

    def count(self, prefix: str = "") -> int:
        with self._lock:
            return sum(1 for k, _, _ in self.items if k.startswith(prefix))


@pytest.fixture
def bag_process(router: InProcessRouter, log_dir: Path) -> Iterator[Callable[..., Process]]:
    """Start `buddybot bag ARGS...` against the test router; every one started is
    stopped when the test ends, also when it fails half-way."""
    started: list[Process] = []

    def start(*args: str) -> Process:
        proc = Process(buddybot_argv("bag", *args, "--connect", router.endpoint),
                       f"bag-{args[0]}", log_dir)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()


def run_bag(router: InProcessRouter, *args: str, timeout: float = 60
            ) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("bag", *args, "--connect", router.endpoint),
                          capture_output=True, text=True, timeout=timeout)


def wait_exit(proc: Process, timeout: float = 60) -> int:
    code = proc.proc.wait(timeout)
    proc.stop()
    return code


@pytest.fixture
def quiet(node_factory: Callable[..., Node]) -> Node:
    """A probe node: it publishes no diagnostics of its own into recordings."""
    return node_factory("bag-test", probe=True)


@pytest.mark.integration
def test_record_info_play_round_trip(router: InProcessRouter, quiet: Node, tmp_path: Path,
                                     bag_process: Callable[..., Process]) -> None:
    """Every topic published once is recorded, described and replayed byte for byte
    (images as decodable JPEG with --images)."""
    out = tmp_path / "rt.mcap"
    found = samples()
    publishers = {key: quiet.raw_publisher(key, topic.encoding)
                  for key, (topic, _payload) in found.items()}
    recorder = bag_process("record", "-o", str(out), "--images",
                           "--duration", "8")
    debug_image = concrete_key(keys.DEBUG_IMAGE)  # not recorded by default: the camera draws it
    # Every recorded key's subscription known here, whatever order they were declared in.
    retry_until(lambda: all(p.has_subscribers() for k, p in publishers.items()
                            if k != debug_image), 30, 0.05, "the recorder subscribed to all")
    for key, (_topic, payload) in found.items():
        publishers[key].put(payload)
    assert wait_exit(recorder) == 0, recorder.output()
    assert "recorded" in recorder.output()

    info = run_bag(router, "info", str(out), "--json")
    assert info.returncode == 0, info.stderr
    shown = json.loads(info.stdout)
    counts = {c["key"]: c["count"] for c in shown["channels"]}
    recorded = set(found) - {debug_image}
    assert {k: counts.get(k) for k in recorded} == {k: 1 for k in recorded}
    assert debug_image not in counts
    assert counts[bag.annotations_key(concrete_key(keys.FACES))] == 1

    latched = frozenset(k for k in recorded if found[k][0].latched)
    received = RawCollector(quiet, latched=latched)
    played = run_bag(router, "play", str(out), "--wait", "10")
    assert played.returncode == 0, played.stderr
    assert "played" in played.stderr
    try:
        retry_until(lambda: all(received.on(k) for k in recorded), 20, 0.05, "every key")
    except TimeoutError:
        pytest.fail(f"not replayed: {sorted(k for k in recorded if not received.on(k))}; "
                    f"player: {played.stderr}")
    for key in recorded:
        topic, payload = found[key]
        (got, _t), *more = received.on(key)
        assert not more, key
        if channels.is_image(topic):
            image = topic.codec.decode(got, m.Image)
            assert image.encoding == "jpeg" and image.stamp_ns == \
                topic.codec.decode(payload, m.Image).stamp_ns
            assert cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR) \
                is not None
        else:
            assert got == payload, key
    assert not received.on(bag.annotations_key(concrete_key(keys.FACES)))


@pytest.mark.integration
def test_sigterm_finishes_the_file(quiet: Node, tmp_path: Path,
                                   bag_process: Callable[..., Process]) -> None:
    out = tmp_path / "term.mcap"
    key = concrete_key(keys.EYE_CONTROL)
    recorder = bag_process("record", "-o", str(out), "eyes/control")
    sent = 0
    with quiet.raw_publisher(key, keys.EYE_CONTROL.encoding) as publisher:
        retry_until(publisher.has_subscribers, 30, 0.05, "the recorder subscribed")
        end = time.monotonic() + 30
        while sent < 20 and time.monotonic() < end:  # 1 s of messages, 20 Hz
            publisher.put(keys.EYE_CONTROL.codec.encode(
                m.EyeControl(stamp_ns=m.now_ns(), yaw=0.1, pitch=0.0, target_distance_cm=100.0)))
            sent += 1
            time.sleep(0.05)  # the publishing rate, not a synchronisation
        recorder.send_signal(signal.SIGTERM)
        assert wait_exit(recorder) == 0, recorder.output()
    recording = bag.open_recording(out)
    assert 0 < recording.info.messages <= sent
    assert recording.info.metadata["robot"] == "buddy"


@pytest.mark.integration
def test_record_refuses_an_unknown_key(router: InProcessRouter, tmp_path: Path) -> None:
    result = run_bag(router, "record", "-o", str(tmp_path / "x.mcap"), "radar/nope")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == (
        "buddybot bag: radar/nope: matches no topic of the catalogue (see `buddybot keys`)")
    assert not (tmp_path / "x.mcap").exists()


def pupil_recording(path: Path, n: int = 21, step_s: float = 0.1, robot: str = "buddy") -> str:
    """n pupil messages `step_s` apart, on robot `robot`; returns the key."""
    key = concrete_key(keys.PUPIL, robot)
    base = time.time_ns()
    items = [(key, keys.PUPIL.codec.encode(m.PupilControl(stamp_ns=m.now_ns(),
                                                          dilation_percentage=i)),
              base + round(i * step_s * 1e9)) for i in range(n)]
    write_recording(path, items, robot=robot)
    return key


@pytest.mark.integration
@pytest.mark.parametrize("damage", ["truncated", "flipped"])
def test_a_damaged_file_publishes_nothing(router: InProcessRouter, quiet: Node, tmp_path: Path,
                                          damage: str) -> None:
    good = tmp_path / "good.mcap"
    key = pupil_recording(good)
    data = good.read_bytes()
    broken = tmp_path / "broken.mcap"
    if damage == "truncated":
        broken.write_bytes(data[: len(data) * 2 // 3])
    else:
        flipped = bytearray(data)
        flipped[len(data) // 3] ^= 0xFF  # inside the chunk of messages
        broken.write_bytes(bytes(flipped))
    received = RawCollector(quiet)
    result = run_bag(router, "play", str(broken))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"buddybot bag: {broken}: ")
    assert ("truncated" if damage == "truncated" else "damaged") in lines[0]
    # The same path with the good file delivers: so "nothing" below means something.
    assert run_bag(router, "play", str(good)).returncode == 0
    retry_until(lambda: len(received.on(key)) == 21, 20, 0.05, "the good file replayed")
    # All from the good file (and its player's diagnostics), none from the broken one.
    assert received.count() - received.count("buddybot/buddy/diagnostics/") == 21


def span(times: list[float]) -> float:
    return max(times) - min(times)


@pytest.mark.integration
def test_rate_start_and_robot(router: InProcessRouter, quiet: Node, tmp_path: Path) -> None:
    path = tmp_path / "pupil.mcap"
    key = pupil_recording(path)  # 2.0 s
    received = RawCollector(quiet)

    assert run_bag(router, "play", str(path)).returncode == 0
    retry_until(lambda: len(received.on(key)) == 21, 20, 0.05, "21 at rate 1")
    normal = span([t for _, t in received.on(key)])
    assert 1.8 < normal < 2.4, normal

    received.items.clear()
    assert run_bag(router, "play", str(path), "--rate", "2").returncode == 0
    retry_until(lambda: len(received.on(key)) == 21, 20, 0.05, "21 at rate 2")
    fast = span([t for _, t in received.on(key)])
    assert 0.85 < fast < 1.2, fast

    received.items.clear()
    assert run_bag(router, "play", str(path), "--start", "1.0").returncode == 0
    retry_until(lambda: len(received.on(key)) == 11, 20, 0.05, "the last 11")
    values = [msg.dilation_percentage for msg in
              (keys.PUPIL.codec.decode(p, m.PupilControl) for p, _ in received.on(key))]
    assert values == list(range(10, 21))

    received.items.clear()
    other = "buddybot/robot2/eyes/pupil"
    assert run_bag(router, "play", str(path), "--robot", "robot2", "--rate", "4"
                   ).returncode == 0
    retry_until(lambda: len(received.on(other)) == 21, 20, 0.05, "21 on robot2")
    assert received.count("buddybot/buddy/") == 0


@pytest.mark.integration
def test_loop_repeats_until_stopped(quiet: Node, tmp_path: Path,
                                    bag_process: Callable[..., Process]) -> None:
    path = tmp_path / "loop.mcap"
    key = pupil_recording(path, n=5, step_s=0.1)
    received = RawCollector(quiet)
    player = bag_process("play", str(path), "--loop", "--rate", "2")
    retry_until(lambda: len(received.on(key)) >= 10, 30, 0.05, "two loops")
    player.send_signal(signal.SIGINT)
    assert wait_exit(player, 10) == 0
    assert "loops (stopped)" in player.output()
    values = [keys.PUPIL.codec.decode(p, m.PupilControl).dilation_percentage
              for p, _ in received.on(key)]
    assert values[:10] == [0, 1, 2, 3, 4] * 2


@pytest.mark.integration
def test_latched_keys_reach_late_subscribers_and_unknown_channels_are_named(
        node_factory: Callable[..., Node], tmp_path: Path,
        bag_process: Callable[..., Process]) -> None:
    """A latched key is replayed as services publish it: a subscriber that comes
    after the message still gets it."""
    path = tmp_path / "latched.mcap"
    key = concrete_key(keys.PRESENCE)
    payload = keys.PRESENCE.codec.encode(m.PresenceDetection(
        stamp_ns=m.now_ns(), target_state=m.PresenceTarget.STANDING,
        presence_state=m.PresenceState.IN_RANGE, distance_m=1.0))
    pupil = concrete_key(keys.PUPIL)
    base = time.time_ns()
    write_recording(path, [(key, payload, base)] + [
        (pupil, keys.PUPIL.codec.encode(m.PupilControl(stamp_ns=m.now_ns(),
                                                       dilation_percentage=1)),
         base + i * 1_000_000_000) for i in range(1, 30)])
    player = bag_process("play", str(path))
    watcher = node_factory("watcher", probe=True)
    pupils = RawCollector(watcher, pupil)
    retry_until(lambda: pupils.on(pupil), 30, 0.05, "the replay under way")
    late = RawCollector(node_factory("late", probe=True), key)  # no history: not yet...
    from buddybot.tools.testing import Collector

    typed = Collector[m.PresenceDetection](node_factory("late-typed"), keys.PRESENCE)
    typed.wait_for(lambda p: p.distance_m == 1.0, 20, "the latched presence")
    assert not late.on(key)  # a plain subscriber after the put gets nothing: history did it
    player.send_signal(signal.SIGINT)
    assert wait_exit(player, 10) == 0


@pytest.mark.integration
def test_a_decompression_bomb_is_refused_before_it_is_inflated(tmp_path: Path) -> None:
    """34 kB holding a 1 GiB message: refused from the chunk's declared size, with
    the player's memory a fraction of the message (it took 2.1 GB before)."""
    path = tmp_path / "bomb.mcap"
    assert write_bomb(path, 1 << 30) < 64 * 1024
    for verb in ("play", "info"):
        result, peak_kb = run_measured(buddybot_argv("bag", verb, str(path)))
        assert peak_kb < 256 * 1024, peak_kb
        if verb == "info":  # the summary alone is fine: info reads nothing else
            assert result.returncode == 0, result.stderr
            continue
        assert result.returncode == 1, result.stderr
        lines = result.stderr.strip().splitlines()
        assert lines == [f"buddybot bag: {path}: refused: a chunk of 1073741855 bytes is over "
                         f"the limit of {mcap_records.MAX_CHUNK_BYTES} bytes (64 MiB)"]


_MEASURE = ("import resource, subprocess, sys\n"
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "sys.stderr.write(r.stderr)\n"
            "print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")


def run_measured(argv: list[str]) -> tuple[subprocess.CompletedProcess[str], int]:
    """Run `argv` under a fresh parent that reports its peak RSS (kB): (result, peak)."""
    outer = subprocess.run([sys.executable, "-c", _MEASURE, *argv], capture_output=True,
                           text=True, timeout=120)
    status, peak = outer.stdout.split()
    return subprocess.CompletedProcess(argv, int(status), "", outer.stderr), int(peak)


def noise_jpeg(seed: int) -> bytes:
    """A JPEG of noise (about 60 kB: it hardly compresses, so chunks fill fast)."""
    pixels = np.random.default_rng(seed).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    ok, data = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    return data.tobytes()


def publish_images(node: Node, until: Callable[[], bool], limit: int = 2000) -> int:
    """Camera frames (JPEG) on camera/front/image until `until()`; how many."""
    key = concrete_key(keys.CAMERA_IMAGE)
    frames = [noise_jpeg(i) for i in range(4)]
    sent = 0
    with node.raw_publisher(key, keys.CAMERA_IMAGE.encoding) as publisher:
        retry_until(publisher.has_subscribers, 30, 0.05, "the recorder subscribed")
        while sent < limit and not until():
            publisher.put(keys.CAMERA_IMAGE.codec.encode(m.Image(
                stamp_ns=m.now_ns(), frame_id="front", width=320, height=240,
                encoding="jpeg", data=frames[sent % len(frames)])))
            sent += 1
            time.sleep(0.01)  # the publishing rate, not a synchronisation
    return sent


@pytest.mark.integration
def test_a_recording_killed_with_sigkill_is_recovered_to_its_last_chunk(
        quiet: Node, tmp_path: Path, bag_process: Callable[..., Process]) -> None:
    cut = tmp_path / "killed.mcap"
    recorder = bag_process("record", "-o", str(cut), "camera/*/image")
    publish_images(quiet, lambda: cut.exists() and cut.stat().st_size > 3 * bag.CHUNK_BYTES)
    recorder.proc.kill()
    recorder.proc.wait(30)
    refused = subprocess.run(buddybot_argv("bag", "info", str(cut)), capture_output=True,
                             text=True, timeout=60)
    assert refused.returncode == 1 and "truncated" in refused.stderr
    fixed = tmp_path / "fixed.mcap"
    result = subprocess.run(buddybot_argv("bag", "recover", str(cut), "-o", str(fixed)),
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    [line] = result.stderr.strip().splitlines()
    recovered = int(line.split()[1])
    assert line.startswith("recovered ") and line.endswith(f"-> {fixed}") and recovered >= 3
    recording = bag.open_recording(fixed)  # what `play` checks: the whole file
    assert recording.info.messages == recovered == len(list(recording.messages()))
    print(f"kill -9: recovered {recovered} messages: {line}")


@pytest.mark.integration
def test_a_full_disk_ends_with_an_exact_summary_and_a_recoverable_file(
        router: InProcessRouter, quiet: Node, tmp_path: Path) -> None:
    """The disk is made full with RLIMIT_FSIZE in the recorder (EFBIG, SIGXFSZ
    ignored): the summary said "0.0 MB" and the file was unusable before."""
    out = tmp_path / "full.mcap"
    limit = 2_000_000

    def small_disk() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    recorder = subprocess.Popen(
        buddybot_argv("bag", "record", "-o", str(out), "camera/*/image",
                      "--connect", router.endpoint),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=small_disk)
    try:
        publish_images(quiet, lambda: recorder.poll() is not None)
        _stdout, stderr = recorder.communicate(timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait(30)
    assert recorder.returncode == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 2 and "Traceback" not in stderr, stderr
    size = out.stat().st_size
    assert 0 < size <= limit
    found = bag_recover.scan(out)
    assert lines[0].startswith(f"recorded {found.messages} of ")
    assert (f", {found.readable_bytes / 1e6:.1f} MB readable of {size / 1e6:.1f} MB written"
            in lines[0])
    assert lines[1].startswith(f"buddybot bag: writing {out} failed: File too large; ")
    assert f"copies its {found.messages} messages" in lines[1]
    fixed = tmp_path / "fixed.mcap"
    result = subprocess.run(buddybot_argv("bag", "recover", str(out), "-o", str(fixed)),
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert bag.open_recording(fixed).info.messages == found.messages > 0
    print(f"full disk: {lines[0]}")


@pytest.mark.integration
def test_a_recorded_robot_id_of_thousands_of_characters_is_not_used(
        router: InProcessRouter, tmp_path: Path) -> None:
    """The file's metadata names the player's robot; an invalid one was a traceback."""
    path = tmp_path / "long-robot.mcap"
    key = concrete_key(keys.PUPIL)
    write_recording(path, [(key, keys.PUPIL.codec.encode(
        m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=3)), time.time_ns())],
        robot="r" * 5000)
    result = run_bag(router, "play", str(path), "--wait", "0")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("played 1 messages on 1 keys")
