"""Zenoh's log pipe can never stall Zenoh.

Fd 1 is a pipe read by a Python thread (`session.route_zenoh_log`). If that
thread cannot run (the GIL held elsewhere) while Zenoh floods lines, a
blocking pipe fills and Zenoh's own threads stop in `write(1)`. The write
end is non-blocking, so a full pipe refuses the write at once: the writer
here plays Zenoh, the reader is simply not started until the pipe is full.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Iterator

import pytest

from buddybot.runtime import session
from buddybot.tools.testing import retry_until

LINE = b"2026-11-23T12:00:00.000000Z  WARN ThreadId(02) zenoh::net::test: flood line %06d\n"


class Writer(threading.Thread):
    """Writes Zenoh-like lines until `refusals` writes in a row were refused (or the
    pipe broke); `done` is set when it stops, which a blocked writer never does."""

    def __init__(self, fd: int, refusals: int = 50) -> None:
        super().__init__(daemon=True)
        self.fd = fd
        self.refusals = refusals
        self.written = 0       # whole lines in the pipe
        self.refused = 0
        self.done = threading.Event()

    def run(self) -> None:
        try:
            in_a_row = 0
            while in_a_row < self.refusals:
                try:
                    os.write(self.fd, LINE % self.written)
                except BlockingIOError:
                    self.refused += 1
                    in_a_row += 1
                    continue
                except BrokenPipeError:
                    return
                self.written += 1
                in_a_row = 0
        finally:
            self.done.set()


class Ends:
    """The two ends of a fresh log pipe; each closed once, by whoever owns it last."""

    def __init__(self) -> None:
        self.read, self.write = session.open_log_pipe()
        self.open = {self.read, self.write}

    def close(self, fd: int) -> None:
        if fd in self.open:
            self.open.discard(fd)
            os.close(fd)

    def handed_over(self, fd: int) -> None:
        """`fd` is closed by someone else now (the pump closes its read end)."""
        self.open.discard(fd)


@pytest.fixture
def log_pipe() -> Iterator[Ends]:
    ends = Ends()
    yield ends
    for fd in list(ends.open):
        ends.close(fd)


def test_a_full_pipe_refuses_the_writer_at_once(log_pipe: Ends) -> None:
    read_end, write_end = log_pipe.read, log_pipe.write
    writer = Writer(write_end)
    writer.start()
    # The reader never runs: with a blocking pipe the writer would be stuck forever.
    assert writer.done.wait(30), "the writer blocked on the full pipe"
    assert writer.refused >= writer.refusals
    assert writer.written * len(LINE % 0) >= 60_000  # at least the kernel's default room
    assert session._full(write_end)
    os.read(read_end, 1 << 16)   # what the reader's check sees once there is room
    assert not session._full(write_end)


def test_the_same_writer_blocks_on_an_ordinary_pipe() -> None:
    """The hazard itself (so the test above can fail): a blocking pipe nobody reads
    holds its writer until the reader goes away."""
    read_end, write_end = os.pipe()
    writer = Writer(write_end)
    writer.start()
    try:
        assert not writer.done.wait(1.0), "an ordinary pipe did not block its writer"
    finally:
        os.close(read_end)   # the blocked write now fails with EPIPE: the writer ends
        assert writer.done.wait(30)
        os.close(write_end)


def test_the_reader_counts_the_overflow_and_loses_no_whole_line(
        log_pipe: Ends, caplog: pytest.LogCaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    read_end, write_end = log_pipe.read, log_pipe.write
    writer = Writer(write_end)
    writer.start()
    assert writer.done.wait(30)
    monkeypatch.setitem(session._overflow, "logged_at", -1e9)  # no earlier warning
    before = session.zenoh_log_overflows()
    passthrough_read, passthrough = os.pipe()
    caplog.set_level(logging.WARNING)
    log_pipe.handed_over(read_end)  # the pump closes it
    pump = threading.Thread(target=session._pump_zenoh_log,
                            args=(read_end, passthrough, write_end), daemon=True)
    pump.start()
    flood = retry_until(lambda: [r for r in caplog.records if r.name == "zenoh"]
                        if sum(r.name == "zenoh" for r in caplog.records) >= writer.written
                        else None, 60, what="every accepted line logged")
    log_pipe.close(write_end)  # the last writer goes: the pump ends at end of file
    pump.join(60)
    assert not pump.is_alive()
    os.close(passthrough)
    with open(passthrough_read, "rb") as other:
        assert other.read() == b""  # every line was recognised as Zenoh's
    assert session.zenoh_log_overflows() == before + 1
    assert len(flood) == writer.written  # each accepted write is one whole line
    assert flood[-1].getMessage().endswith(f"flood line {writer.written - 1:06d}")
    warned = [r for r in caplog.records if "log pipe was full" in r.getMessage()]
    assert len(warned) == 1 and warned[0].levelno == logging.WARNING


class PanicException(BaseException):
    """What pyo3 raises for a Rust panic: a BaseException, not an Exception."""


def test_zenoh_failing_to_start_for_want_of_descriptors_is_tried_again(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """A flood of connections on a process's web server can leave Zenoh no
    descriptor for its runtime ("Failed to init tx", a panic): the session is
    opened again once they are back, not left waiting for ever."""
    opened = object()
    calls: list[int] = []

    def fake_open(_config: object) -> object:
        calls.append(1)
        if len(calls) == 1:
            raise PanicException("Failed to init tx")
        return opened

    monkeypatch.setattr(session.zenoh, "open", fake_open)
    monkeypatch.setattr(session, "RETRY_S", 0.05)
    with caplog.at_level(logging.WARNING, logger="buddybot.node"):
        got = session.open_session(session.zenoh.Config(), threading.Event())
    assert got is opened and len(calls) == 2
    assert "out of file descriptors" in caplog.text


def test_any_other_failure_to_open_is_unreachable_at_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    def fake_open(_config: object) -> object:
        raise session.zenoh.ZError("Unable to connect to any of [tcp/127.0.0.1:1]")

    monkeypatch.setattr(session.zenoh, "open", fake_open)
    with pytest.raises(session.RouterUnreachable):
        session.open_session(session.zenoh.Config(), threading.Event())


def test_a_stop_while_waiting_to_try_again_returns_none(
        monkeypatch: pytest.MonkeyPatch) -> None:
    stop = threading.Event()

    def fake_open(_config: object) -> object:
        stop.set()
        raise PanicException("Failed to init tx")

    monkeypatch.setattr(session.zenoh, "open", fake_open)
    assert session.open_session(session.zenoh.Config(), stop) is None
