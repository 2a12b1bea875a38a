"""One reading of an endpoint: `up`, `buddybot router` and `doctor` agree on every case.

The same table goes through what each of them uses (the host and port, is it
loopback, is its port taken), so a locator one of them reads differently from
another (a `#iface=lo` suffix, the whole 127.0.0.0/8, IPv6 brackets) fails here.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from buddybot.runtime import endpoints
from buddybot.runtime.config import DEFAULT_ENDPOINT
from buddybot.supervisor import launch, router
from buddybot.tools import doctor
from buddybot.tools.doctor import FAIL, OK
from buddybot.tools.testing import LOOPBACK

CASES = [  # locator, host, port, loopback
    ("tcp/127.0.0.1:7447", "127.0.0.1", 7447, True),
    ("tcp/127.0.0.1:7447#iface=lo", "127.0.0.1", 7447, True),
    ("tcp/127.0.0.1:7447?prio=1-7#iface=lo", "127.0.0.1", 7447, True),
    ("tls/127.0.1.1:7448", "127.0.1.1", 7448, True),
    ("tcp/localhost:7447", "localhost", 7447, True),
    ("tcp/LocalHost:7447", "LocalHost", 7447, True),
    ("tcp/[::1]:7447", "::1", 7447, True),
    ("tls/[::1]:7447#iface=lo", "::1", 7447, True),
    ("tcp/0.0.0.0:7447", "0.0.0.0", 7447, False),
    ("tcp/[::]:7447", "::", 7447, False),
    ("tcp/192.168.1.20:7447", "192.168.1.20", 7447, False),
    ("tls/robot.local:7447", "robot.local", 7447, False),
    ("tcp/[fe80::1]:7447", "fe80::1", 7447, False),
]


@pytest.mark.parametrize(("locator", "host", "port", "loopback"), CASES)
def test_up_and_doctor_read_an_endpoint_alike(locator: str, host: str, port: int,
                                              loopback: bool) -> None:
    parsed = endpoints.parse(locator)
    assert (parsed.host, parsed.port) == (host, port)
    assert f"{parsed.proto}/{parsed.address}{parsed.suffix}" == locator
    assert endpoints.endpoint_is_loopback(locator) is loopback
    # up: its router listens on the configured endpoint only when that is loopback
    assert (launch.default_listen([locator]) == locator) is loopback
    # up: the services reach its router on the same port, a wildcard through loopback
    local = endpoints.parse(endpoints.connect_endpoint(locator))
    assert local.port == port and local.suffix == parsed.suffix
    assert local.host == (LOOPBACK if endpoints.is_wildcard(host) else host)
    # doctor: this machine (loopback or a wildcard), without DNS or interfaces
    assert doctor.is_local_host(host, (), ()) is (loopback or endpoints.is_wildcard(host))
    assert endpoints.host_port(locator) == (local.host, port)


@pytest.mark.parametrize("locator", ["tcp/", "tcp/127.0.0.1", "tcp/127.0.0.1:x",
                                      "127.0.0.1:7447", "tcp/127.0.0.1:#iface=lo"])
def test_an_endpoint_without_a_port_is_refused(locator: str) -> None:
    with pytest.raises(ValueError):
        endpoints.parse(locator)
    assert not endpoints.endpoint_is_loopback(locator)
    assert not endpoints.accepting(locator)


@pytest.fixture
def no_zenoh_probe(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Whoever holds a taken port answers as a stranger, without a Zenoh probe
    (the look shared by up, router and doctor); the endpoints it was asked about."""
    asked: list[str] = []

    def users(endpoint: str, *_args: object) -> tuple[None, None]:
        asked.append(endpoint)
        return None, None

    monkeypatch.setattr(doctor, "port_users", users)
    yield asked


def verdicts(endpoint: str) -> dict[str, bool]:
    """Whether the port is taken, according to up, router and doctor."""
    check = doctor.port_check(endpoint, None, 1.0)
    assert check.level in (OK, FAIL)
    return {"accepting": endpoints.accepting(endpoint),
            "up": launch._busy([endpoint], None) is not None,
            "router": router.busy_port([endpoint]) is not None,
            "doctor": check.level == FAIL}


def test_up_router_and_doctor_agree_whether_a_port_is_taken(no_zenoh_probe: list[str]
                                                            ) -> None:
    with socket.socket() as holder:
        holder.bind((LOOPBACK, 0))  # bound, not listening: reserved and refusing
        port = holder.getsockname()[1]
        spellings = [f"tcp/{LOOPBACK}:{port}", f"tcp/{LOOPBACK}:{port}#iface=lo",
                     f"tls/{LOOPBACK}:{port}", f"tcp/0.0.0.0:{port}", f"tcp/[::]:{port}",
                     f"tcp/localhost:{port}?prio=1-7"]
        for endpoint in spellings:
            assert set(verdicts(endpoint).values()) == {False}, endpoint
        assert no_zenoh_probe == []
        holder.listen()
        for endpoint in spellings:
            assert set(verdicts(endpoint).values()) == {True}, endpoint
        # a transport that is not TCP is not looked at, by anyone
        assert set(verdicts(f"udp/{LOOPBACK}:{port}").values()) == {False}
    assert all(endpoints.parse(e).port == port for e in no_zenoh_probe)


def test_the_default_endpoint_is_loopback() -> None:
    """`up` with no config listens where the services look by default."""
    assert launch.default_listen([]) == DEFAULT_ENDPOINT
    assert endpoints.endpoint_is_loopback(DEFAULT_ENDPOINT)


def test_a_wildcard_server_is_reached_on_loopback() -> None:
    for host in ("", "0.0.0.0", "::", "[::]"):
        assert endpoints.local_host(host) == LOOPBACK
    assert endpoints.local_host("192.168.1.20") == "192.168.1.20"
