"""The web surfaces' shared rules (services/web/guard.py), pure: the Host
allow-list, the one Origin rule, connection caps, page slots, accept-error logging."""

from __future__ import annotations

import asyncio
import errno
import logging

import pytest
from hypothesis import given
from hypothesis import strategies as st

from buddybot.web.guard import (
    AcceptErrorLog,
    Conn,
    ConnectionTable,
    HostAllowList,
    ListenerWatch,
    Slot,
    descriptor_budget,
    origin_allowed,
    pick_eviction,
    request_port,
    split_host,
)

HOSTS = HostAllowList.make("127.0.0.1", ["robot.example.org"], hostname="Buddy.lan")


def test_default_names_are_loopback_this_machine_and_the_bind_address() -> None:
    assert HOSTS.names == {"localhost", "127.0.0.1", "::1", "buddy.lan", "buddy",
                           "buddy.local", "robot.example.org"}
    wild = HostAllowList.make("0.0.0.0", hostname="b", addresses=["192.168.1.5", "fe80::1"])
    assert {"192.168.1.5", "fe80::1"} <= wild.names and "0.0.0.0" not in wild.names
    assert "10.0.0.7" in HostAllowList.make("10.0.0.7", hostname="b").names


def test_the_address_a_connection_came_in_on_names_this_machine() -> None:
    """An address an interface got after start (DHCP): the socket's own address."""
    hosts = HostAllowList.make("0.0.0.0", hostname="b", addresses=[])
    assert not hosts.allows("192.168.1.77:8090")
    assert hosts.reached_at("192.168.1.77").allows("192.168.1.77:8090")
    assert hosts.reached_at("fe80::5%eth0").allows("[fe80::5]:8090")
    assert not hosts.reached_at("192.168.1.77").allows("evil.test:8090")
    assert hosts.reached_at("127.0.0.1") is hosts


@pytest.mark.parametrize(("host", "ok"), [
    ("127.0.0.1:8090", True), ("LOCALHOST", True), ("[::1]:8090", True),
    ("buddy.local.:8090", True), ("robot.example.org", True),
    ("evil.test:8090", False), ("attacker.example", False), ("127.0.0.2", False),
    ("user@127.0.0.1", False), ("[::1", False), ("", False), (None, True),
])
def test_host_allow_list(host: str | None, ok: bool) -> None:
    assert HOSTS.allows(host) is ok


@pytest.mark.parametrize(("origin", "port", "listed", "ok"), [
    (None, 8080, [], True),                                      # not a browser: allowed
    ("http://127.0.0.1:8080", 8080, [], True),                   # a page served here
    ("HTTP://LocalHost:8080", 8080, [], True),                   # case does not matter
    ("http://buddy.local:8080", 8080, [], True),
    ("https://127.0.0.1:8080", 8080, [], True),                  # scheme only sets the port
    ("http://127.0.0.1", 80, [], True),                          # default port spelled out
    ("http://127.0.0.1:9999", 8080, [], False),                  # same host, other port
    ("http://evil.example", 8080, [], False),                    # another site
    ("http://evil.test:8080", 8080, [], False),                  # DNS rebinding: Host says
    ("null", 8080, [], False),                                   # evil.test too, not asked
    ("null", 8080, ["null"], True),
    ("file:///tmp/x.html", 8080, [], False),
    ("http://127.0.0.1:8080/path", 8080, [], False),
    ("http://user@127.0.0.1:8080", 8080, [], False),
    ("http://[::1", 8080, [], False),
    ("http://127.0.0.1:99999", 8080, [], False),
    ("http://tablet.local:8080", 8080, ["http://tablet.local:8080"], True),
    ("http://TABLET.local:8080", 8080, ["http://tablet.local:8080"], True),
    ("http://tablet.local", 8080, ["http://tablet.local:80"], True),
    ("https://tablet.local:8080", 8080, ["http://tablet.local:8080"], False),
    ("http://127.0.0.1:8080", None, [], True),                   # port not known: any
    ("http://" + "a" * 5000, 8080, [], False),
])
def test_origin_rule(origin: str | None, port: int | None, listed: list[str],
                     ok: bool) -> None:
    assert origin_allowed(origin, HOSTS, port=port, listed=listed) is ok


def test_origin_rule_for_a_server_serving_no_page() -> None:
    """The Foxglove bridge: listed app origins and loopback pages, any port."""
    app = ["https://app.foxglove.dev", "file://"]
    for origin in ("https://app.foxglove.dev", "file://", "http://localhost:3000",
                   "http://127.0.0.1:8080", "http://[::1]:5173"):
        assert origin_allowed(origin, None, listed=app, loopback_any_port=True), origin
    for origin in ("http://evil.example", "https://app.foxglove.dev.evil.example", "null",
                   "http://buddy.local:8765"):
        assert not origin_allowed(origin, None, listed=app, loopback_any_port=True), origin


@given(st.text(max_size=300), st.text(max_size=60))
def test_rules_never_raise(origin: str, host: str) -> None:
    assert origin_allowed(origin, HOSTS, port=request_port(host),
                          listed=["http://a:1", "http://[bad"]) in (True, False)
    assert HOSTS.allows(host) in (True, False)
    assert split_host(host) is None or isinstance(split_host(host), tuple)


def test_request_port() -> None:
    assert request_port("127.0.0.1:8090") == 8090
    assert request_port("buddy") == 80
    assert request_port("buddy", "https") == 443
    assert request_port(None) is None


def test_a_slow_header_flood_gives_way_to_new_connections() -> None:
    table = ConnectionTable(per_address=3, total=5)
    cut: list[str] = []

    def conn(address: str, t: float, name: str) -> Conn:
        return Conn(address, t, close=lambda: cut.append(name))

    for i in range(3):
        assert table.admit(conn("10.0.0.1", i, f"slow{i}")) == (True, None)
    ok, victim = table.admit(conn("10.0.0.1", 9, "user"))
    assert ok and victim is not None and victim.opened == 0   # the oldest slow one goes
    for c in table.conns:
        c.done = True                                       # all finished their headers
    ok, victim = table.admit(conn("10.0.0.1", 10, "more"))
    assert not ok and victim is None and table.refused == 1
    table.admit(conn("10.0.0.2", 11, "b1"))
    table.admit(conn("10.0.0.3", 12, "b2"))                 # total reached (5)
    ok, victim = table.admit(conn("10.0.0.4", 13, "c"))
    assert ok and victim is not None and victim.address == "10.0.0.2"
    assert table.evicted == 2 and len(table.conns) == 5
    table.release(table.conns[0])
    assert len(table.conns) == 4


def test_descriptor_budget_keeps_descriptors_free() -> None:
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    budget = descriptor_budget(10**9)
    if soft != resource.RLIM_INFINITY:
        assert budget <= soft - 64 and budget >= 1
    assert descriptor_budget(3) == 3


def test_page_slots_go_to_the_newcomer_quietest_and_lowest_first() -> None:
    now = 1000.0
    eight_readers = [Slot(0, now - 100 + i) for i in range(8)]
    assert pick_eviction(eight_readers, 0, now, idle_s=30) == 0   # the longest there
    pinging = [Slot(0, now - 50, heard=now - 1), Slot(0, now - 0.1),
               Slot(0, now - 60, heard=now - 40)]
    assert pick_eviction(pinging, 0, now, idle_s=30) == 2         # idle first
    assert pick_eviction(pinging[:2], 0, now, idle_s=30) == 1     # then never heard
    mixed = [Slot(2, now - 500), Slot(0, now - 1, heard=now), Slot(1, now - 900)]
    assert pick_eviction(mixed, 0, now, idle_s=30) == 1           # only its equals
    assert pick_eviction(mixed, 2, now, idle_s=30) == 1           # the anonymous first
    assert pick_eviction([Slot(2, now)], 0, now, idle_s=30) is None
    assert pick_eviction([], 0, now, idle_s=30) is None


def test_accept_errors_are_counted_and_logged_at_a_bounded_rate(
        caplog: pytest.LogCaptureFixture) -> None:
    handler = AcceptErrorLog(logging.getLogger("test.web"), period_s=60)
    loop = asyncio.new_event_loop()
    try:
        with caplog.at_level(logging.WARNING):
            for _ in range(10_000):
                handler(loop, {"message": "socket.accept() out of system resource",
                               "exception": OSError(errno.EMFILE, "Too many open files")})
            handler(loop, {"message": "Task exception was never retrieved",
                           "exception": RuntimeError("x")})
    finally:
        loop.close()
    assert handler.accept_errors == 10_000 and handler.other_errors == 1
    assert len(caplog.records) == 2
    assert "Too many open files" in caplog.records[0].getMessage()
    assert not any(r.exc_info for r in caplog.records)


def test_listener_watch_sees_a_listener_that_stopped() -> None:
    async def main() -> tuple[bool, bool, str]:
        server = await asyncio.start_server(lambda _r, _w: None, "127.0.0.1", 0)
        watch = ListenerWatch(server)
        before = watch.alive()
        server.close()
        await server.wait_closed()
        return before, watch.alive(), watch.dead

    before, after, why = asyncio.run(main())
    assert before and not after and "stopped serving" in why
    assert not ListenerWatch(None).alive()
