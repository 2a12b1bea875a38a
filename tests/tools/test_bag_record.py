"""The recorder without processes: it never blocks the caller and counts what it drops,
refuses or does not know."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.tools import bag
from buddybot.tools.bag_record import Recorder
from tests.tools.test_bag import concrete_key


class GatedWriter(bag.BagWriter):
    """A real writer whose writes wait for a gate (to fill the recorder's queue)."""

    gate = threading.Event()

    def write(self, key: str, payload: bytes, arrival_ns: int) -> bool:
        self.gate.wait(10)
        return super().write(key, payload, arrival_ns)


def test_the_recorder_never_blocks_and_counts_drops(tmp_path: Path) -> None:
    key = concrete_key(keys.PUPIL)
    good = keys.PUPIL.codec.encode(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=5))
    recorder = Recorder(GatedWriter(tmp_path / "q.mcap", robot="buddy"), max_samples=10)
    started = time.monotonic()
    accepted = [recorder.offer(key, good, time.time_ns() + i) for i in range(50)]
    assert time.monotonic() - started < 1.0  # the writer is stuck, offering is not
    assert 10 <= sum(accepted) <= 20  # the queue, plus a batch the writer may hold
    assert not recorder.offer(key, b"not json", time.time_ns())  # full: dropped at once
    assert not recorder.offer("buddybot/buddy/unknown/key", b"{}", time.time_ns())
    GatedWriter.gate.set()
    final = recorder.close(timeout=10)
    assert final.dropped == 50 - sum(accepted) + 2  # the last two also found it full
    assert final.written == sum(accepted)
    assert bag.read_info(tmp_path / "q.mcap").messages == sum(accepted)


def test_the_recorder_counts_malformed_and_unknown(tmp_path: Path) -> None:
    key = concrete_key(keys.PUPIL)
    good = keys.PUPIL.codec.encode(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=5))
    recorder = Recorder(bag.BagWriter(tmp_path / "r.mcap", robot="buddy"))
    for payload in (good, b"not json", b'{"stamp_ns": 1}', good):
        assert recorder.offer(key, payload, time.time_ns())
    assert recorder.offer("buddybot/buddy/unknown/key", b"{}", time.time_ns())
    final = recorder.close(timeout=10)
    assert (final.written, final.malformed, final.unknown, final.dropped) == (2, 2, 1, 0)
    assert final.bytes == (tmp_path / "r.mcap").stat().st_size
    assert not recorder.offer(key, good, time.time_ns())  # closed: refused, counted
