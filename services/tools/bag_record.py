"""The recorder's hand-off: Zenoh's callbacks queue samples, one thread writes them.

A subscriber callback runs in Zenoh's own thread, and blocking there
starves every other key of the session; compressing a JPEG or waiting for
the disk would. So `offer()` only appends to a bounded queue (bounded in
samples and in bytes: a few camera frames must not take the memory of a
Raspberry Pi) and returns; what does not fit is dropped and counted. The
writer thread converts and writes; a sample its type refuses is counted
and skipped, never written. Pure: no Zenoh here.
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass

from buddybot.contract import channels
from buddybot.tools.bag import BagWriter

QUEUE_SAMPLES = 4096
QUEUE_BYTES = 64 * 1024 * 1024
WRITE_PERIOD_S = 0.05


@dataclass(frozen=True)
class Progress:
    """What the recorder did so far (a snapshot)."""

    written: int
    bytes: int
    dropped: int
    malformed: int
    unknown: int
    queued: int


class Recorder:
    """Writes offered samples with a `BagWriter` on its own thread."""

    def __init__(self, writer: BagWriter, *, max_samples: int = QUEUE_SAMPLES,
                 max_bytes: int = QUEUE_BYTES) -> None:
        self.writer = writer
        self._items: collections.deque[tuple[str, bytes, int]] = collections.deque()
        self._bytes = 0
        self._max_samples = max_samples
        self._max_bytes = max_bytes
        self._cond = threading.Condition()
        self._closing = False
        self.dropped = 0
        self.malformed = 0
        self.unknown = 0
        self.error: BaseException | None = None
        """What stopped the writer (a full disk, say); None while it runs."""
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=True)
        self._thread.start()

    def offer(self, key: str, payload: bytes, arrival_ns: int) -> bool:
        """Queue one sample (never blocks). False: dropped, the queue is full
        or the recorder is closing (counted as dropped)."""
        size = len(payload)
        with self._cond:
            if (self._closing or self.error is not None
                    or len(self._items) >= self._max_samples
                    or (self._items and self._bytes + size > self._max_bytes)):
                self.dropped += 1
                return False
            self._items.append((key, payload, arrival_ns))
            self._bytes += size
        return True  # no notify: the writer polls (one wake-up per batch, not per sample)

    def progress(self) -> Progress:
        with self._cond:
            return Progress(self.writer.stats.messages, self.writer.bytes_written, self.dropped,
                            self.malformed, self.unknown, len(self._items))

    def _run(self) -> None:
        """Every WRITE_PERIOD_S, write what arrived meanwhile (a thread woken per
        sample cost more CPU than writing it: measured with benchmarks/bag.py)."""
        while True:
            with self._cond:
                if not self._items and not self._closing:
                    self._cond.wait(WRITE_PERIOD_S)
                batch = list(self._items)
                self._items.clear()
                self._bytes = 0
                closing = self._closing
            for key, payload, arrival_ns in batch:
                try:
                    if not self.writer.write(key, payload, arrival_ns):
                        self.unknown += 1
                except channels.ChannelError:
                    self.malformed += 1
                except Exception as exc:  # the disk is full, the file went away: stop writing
                    with self._cond:
                        self.error = exc
                        self._items.clear()
                        self._bytes = 0
                    return
            if closing and not batch:
                return

    def close(self, timeout: float | None = None) -> Progress:
        """Write what is queued, then the file's summary and index; the final counts.

        The file is finalised even after a write error, so what was written opens."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        self._thread.join(timeout)
        try:
            self.writer.close()
        except Exception as exc:
            if self.error is None:
                self.error = exc
        return self.progress()
