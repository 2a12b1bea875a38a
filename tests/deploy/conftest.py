"""Fixtures for the deployment profile: real certificates, a real TLS + ACL router.

The Zenoh files under deploy/zenoh/ name certificates under /etc/buddybot/certs/;
`HostProfile.zenoh_file` copies a file with those paths pointed at certificates that
scripts/make-test-certs.sh made in a temporary folder, so the tests run the shipped
files, changed in nothing but where the certificates are.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from buddybot.core.node import Node, zenoh_config
from buddybot.core.testing import (
    LOOPBACK,
    Process,
    buddybot_argv,
    free_port,
    stop_and_report,
    wait_port,
)

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"
ZENOH_DIR = DEPLOY / "zenoh"
SYSTEMD_DIR = DEPLOY / "systemd"
CERT_SCRIPT = REPO / "scripts" / "make-test-certs.sh"
INSTALLED_CERTS = "/etc/buddybot/certs/"
HOSTS = ("robot", "radar-board", "eye-screen", "operator")


def make_certs(folder: Path, *router_names: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", str(CERT_SCRIPT), str(folder), *router_names],
                          capture_output=True, text=True, timeout=120, check=False)


@dataclass
class HostProfile:
    """The deploy files with certificate paths pointed at one test CA's folder."""

    certs: Path
    work: Path

    def zenoh_file(self, name: str, cert_name: str | None = None) -> str:
        """deploy/zenoh/NAME.json5 with this profile's certificates.

        `cert_name` swaps the host's certificate and key for another pair from the
        certificate folder (e.g. "rogue"), to play a client that is not who it says.
        """
        text = (ZENOH_DIR / f"{name}.json5").read_text()
        text = text.replace(INSTALLED_CERTS, f"{self.certs}/")
        if cert_name is not None:
            text = text.replace(f"{self.certs}/{name}.", f"{self.certs}/{cert_name}.")
        out = self.work / f"{name}-as-{cert_name or name}.json5"
        out.write_text(text)
        return str(out)

    def toml(self, host: str, endpoint: str, robot: str = "buddy",
             cert_name: str | None = None) -> Path:
        """A BuddyBot config for one host: where the router is and which TLS file to use."""
        path = self.work / f"{host}-as-{cert_name or host}.toml"
        path.write_text(
            f'[robot]\nid = "{robot}"\n[zenoh]\nconnect = ["{endpoint}"]\n'
            f'config_file = "{self.zenoh_file(host, cert_name)}"\n'
        )
        return path


@pytest.fixture(scope="session")
def cert_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One test CA and host certificates, made once by the shipped script."""
    folder = tmp_path_factory.mktemp("certs")
    done = make_certs(folder)
    assert done.returncode == 0, done.stderr
    return folder


@pytest.fixture
def profile(cert_dir: Path, tmp_path: Path) -> HostProfile:
    work = tmp_path / "zenoh"
    work.mkdir()
    return HostProfile(cert_dir, work)


@dataclass
class TlsRouter:
    process: Process
    endpoint: str
    port: int


@pytest.fixture
def tls_router(profile: HostProfile, tmp_path: Path) -> Iterator[TlsRouter]:
    """`buddybot router` with deploy/zenoh/router.json5 on a free loopback TLS port."""
    port = free_port()
    endpoint = f"tls/{LOOPBACK}:{port}"
    argv = buddybot_argv("router", "--listen", endpoint,
                         "--zenoh-config", profile.zenoh_file("router"))
    proc = Process(argv, f"tls-router-{port}", tmp_path / "logs")
    try:
        wait_port(port)
        yield TlsRouter(proc, endpoint, port)
    finally:
        proc.stop()
        print(f"--- router log ---\n{proc.output()[-3000:]}")


def open_client(endpoint: str, zenoh_file: str | None, timeout_ms: int = 4000) -> zenoh.Session:
    """A plain client session that gives up after `timeout_ms` (raises zenoh.ZError)."""
    config = zenoh_config(connect=[endpoint], base_file=zenoh_file)
    config.insert_json5("connect/timeout_ms", str(timeout_ms))
    return zenoh.open(config)


@pytest.fixture
def host_node(profile: HostProfile, tls_router: TlsRouter) -> Iterator[Callable[..., Node]]:
    """Nodes connected through the TLS router as one of the deploy hosts."""
    made: list[Node] = []

    def make(host: str, name: str) -> Node:
        node = Node(name, connect=[tls_router.endpoint],
                    zenoh_config_file=profile.zenoh_file(host))
        made.append(node)
        return node

    yield make
    for node in reversed(made):
        node.close()


@pytest.fixture
def host_process(profile: HostProfile, tls_router: TlsRouter,
                 tmp_path: Path) -> Iterator[Callable[..., Process]]:
    """`buddybot ARGS... --config HOST.toml` processes, stopped (and shown) afterwards."""
    started: list[Process] = []

    def start(host: str, *args: str, cert_name: str | None = None) -> Process:
        config = profile.toml(host, tls_router.endpoint, cert_name=cert_name)
        argv = buddybot_argv(*args, "--config", str(config))
        label = re.sub(r"[^\w.-]+", "_", "-".join(args[:2]))
        proc = Process(argv, f"{host}-{label}-{len(started)}", tmp_path / "logs")
        started.append(proc)
        return proc

    yield start
    stop_and_report(started, tail=3000)
