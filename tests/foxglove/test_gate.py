"""The Foxglove bridge's gate (services/foxglove/gate.py) in this process: the
handshake's fields, and a gate whose upstream or own listener is gone."""

from __future__ import annotations

import logging
import socket

import pytest

from buddybot.foxglove.gate import Gate, head_fields, sdk_listening
from buddybot.runtime.errors import ServeError
from buddybot.tools.testing import http_status
from buddybot.web.guard import Guard, HostAllowList, Limits


def gate(upstream_port: int) -> Gate:
    guard = Guard(HostAllowList.make("127.0.0.1", hostname="buddy"), Limits(2.0, 8, 4),
                  logging.getLogger("test.gate"), per_connection=3)
    return Gate(guard, ["https://app.foxglove.dev"], upstream_port)


def test_head_fields() -> None:
    head = (b"GET / HTTP/1.1\r\nHost: a:1\r\nORIGIN: http://x\r\nOrigin: http://y\r\n"
            b"junk\r\n: empty\r\n\r\n")
    assert head_fields(head) == {"host": "a:1", "origin": "http://x"}
    assert head_fields(b"\xff\xfe") == {}


def test_the_gate_refuses_before_it_forwards_and_knows_when_upstream_is_gone() -> None:
    with socket.socket() as upstream:
        upstream.bind(("127.0.0.1", 0))
        upstream.listen()
        port = upstream.getsockname()[1]
        assert sdk_listening(port) is True
        g = gate(port)
        served = g.start("127.0.0.1", 0)
        try:
            assert g.alive()
            assert http_status(served, websocket=True, origin="http://evil.example") == 403
            assert http_status(served, websocket=True, host="evil.test") == 421
            assert g.counters()["origins_refused"] == 1
            assert g.counters()["hosts_refused"] == 1
        finally:
            upstream.close()
        g.check_upstream()
        assert not g.alive() and "gone" in g.why_dead()
        assert not g.alive()   # for good
        g.stop()


def test_a_busy_port_is_a_serve_error() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with pytest.raises(ServeError, match="Address already in use"):
            gate(1).start("127.0.0.1", taken.getsockname()[1])
