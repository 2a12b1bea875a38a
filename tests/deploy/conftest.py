"""Fixtures for the deployment profile: real certificates, a real TLS + ACL router.

The Zenoh files under deploy/zenoh/ name certificates under /etc/buddybot/certs/;
`HostProfile.zenoh_file` copies a file with those paths pointed at certificates that
scripts/make-test-certs.sh made in a temporary folder, so the tests run the shipped
files, changed in nothing but where the certificates are.

`veth_namespace` makes "another host" for the namespace tests (test_netns.py,
test_netfaults.py): a network namespace joined to this one by a veth pair, removed
afterwards even when the test fails.
"""

from __future__ import annotations

import contextlib
import os
import random
import re
import shutil
import subprocess
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import (
    LOOPBACK,
    Process,
    buddybot_argv,
    closed_afterwards,
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
HOSTS = ("robot", "radar-board", "eye-screen", "camera-host", "operator")


def make_certs(folder: Path, *router_names: str) -> subprocess.CompletedProcess[str]:
    """scripts/make-test-certs.sh FOLDER ROUTER_NAMES..., plus any host of HOSTS the
    script does not know yet (see `_add_host_certificate`)."""
    done = subprocess.run(["bash", str(CERT_SCRIPT), str(folder), *router_names],
                          capture_output=True, text=True, timeout=120, check=False)
    if done.returncode == 0:
        for host in HOSTS:
            if not (folder / f"{host}.pem").exists():
                _add_host_certificate(folder, host)
    return done


def _add_host_certificate(folder: Path, host: str) -> None:
    """HOST.pem/HOST.key signed by the folder's test CA, with the extensions the
    script gives every client (CN = HOST, clientAuth, SAN DNS:HOST).

    Only for a host newer than scripts/make-test-certs.sh (camera-host, until the
    script's HOSTS list names it): the profile tests then still run every host.
    """
    key, csr, ext = folder / f"{host}.key", folder / f"{host}.csr", folder / f"{host}.ext"
    ext.write_text("basicConstraints = critical, CA:FALSE\nkeyUsage = critical, "
                   "digitalSignature\nextendedKeyUsage = clientAuth\n"
                   f"subjectAltName = DNS:{host}\nauthorityKeyIdentifier = keyid\n")
    steps = [
        ["genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256",
         "-out", str(key)],
        ["req", "-new", "-key", str(key), "-subj", f"/O=BuddyBot/CN={host}", "-out", str(csr)],
        ["x509", "-req", "-in", str(csr), "-CA", str(folder / "ca.pem"),
         "-CAkey", str(folder / "ca.key"), "-CAcreateserial", "-days", "825", "-sha256",
         "-extfile", str(ext), "-out", str(folder / f"{host}.pem")],
    ]
    for step in steps:
        subprocess.run(["openssl", *step], capture_output=True, text=True, timeout=60,
                       check=True)
    key.chmod(0o600)
    for leftover in (csr, ext, *folder.glob("*.srl")):
        leftover.unlink(missing_ok=True)


def ip(*args: str) -> subprocess.CompletedProcess[str]:
    """`ip ARGS...` (iproute2), never raising: callers look at returncode/stderr."""
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30, check=False)


@dataclass
class Namespace:
    """A network namespace joined to this one by a veth pair on a private /30."""

    name: str
    host_addr: str  # this side of the veth ("the robot computer"): where the router listens
    ns_addr: str  # the namespace's side ("the other host")
    veth_host: str
    veth_ns: str

    @property
    def board_addr(self) -> str:  # the name test_netns.py grew up with
        return self.ns_addr

    def exec_argv(self, *argv: str) -> list[str]:
        """`argv` run inside the namespace."""
        return ["ip", "netns", "exec", self.name, *argv]

    def set_link(self, up: bool) -> None:
        """Plug or unplug the namespace's end of the cable (`ip link set up|down`)."""
        done = ip("-n", self.name, "link", "set", self.veth_ns, "up" if up else "down")
        assert done.returncode == 0, done.stderr


def skip_without_namespaces() -> None:
    if shutil.which("ip") is None or os.geteuid() != 0:
        pytest.skip("needs root and iproute2 to make a network namespace")


@contextlib.contextmanager
def veth_namespace(prefix: str) -> Iterator[Namespace]:
    """A fresh namespace and veth pair (random names and 10.200-249.x.0/30 subnet, so
    parallel runs do not collide); both are deleted afterwards, even on failure.
    Skips the test where namespaces cannot be made (container without CAP_NET_ADMIN)."""
    skip_without_namespaces()
    tag = f"{os.getpid() % 10000}{random.randrange(100):02d}"
    name, veth_host, veth_ns = f"{prefix}{tag}", f"bbh{tag}", f"bbn{tag}"
    subnet = f"10.{random.randrange(200, 250)}.{random.randrange(256)}"
    ns = Namespace(name, f"{subnet}.1", f"{subnet}.2", veth_host, veth_ns)
    made = ip("netns", "add", name)
    if made.returncode != 0:
        pytest.skip(f"cannot make a network namespace: {made.stderr.strip()}")
    try:
        steps = [
            ("link", "add", veth_host, "type", "veth", "peer", "name", veth_ns),
            ("link", "set", veth_ns, "netns", name),
            ("addr", "add", f"{ns.host_addr}/30", "dev", veth_host),
            ("link", "set", veth_host, "up"),
            ("-n", name, "addr", "add", f"{ns.ns_addr}/30", "dev", veth_ns),
            ("-n", name, "link", "set", veth_ns, "up"),
            ("-n", name, "link", "set", "lo", "up"),
        ]
        for step in steps:
            done = ip(*step)
            if done.returncode != 0:
                pytest.skip(f"ip {' '.join(step)}: {done.stderr.strip()}")
        yield ns
    finally:
        ip("link", "del", veth_host)  # removes both ends
        ip("netns", "del", name)


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
    def make(host: str, name: str) -> Node:
        return Node(name, connect=[tls_router.endpoint],
                    zenoh_config_file=profile.zenoh_file(host))

    yield from closed_afterwards(make)


@pytest.fixture
def host_process(profile: HostProfile, tls_router: TlsRouter,
                 tmp_path: Path) -> Iterator[Callable[..., Process]]:
    """`buddybot ARGS... --config HOST.toml` processes, stopped (and shown) afterwards."""
    started: list[Process] = []

    def start(host: str, *args: str, cert_name: str | None = None) -> Process:
        config = profile.toml(host, tls_router.endpoint, cert_name=cert_name)
        argv = buddybot_argv(*args, "--config", str(config))
        label = re.sub(r"[^\w.-]+", "_", "-".join(args[:2]))
        proc = Process(argv, f"{host}-{label}-{len(started)}", tmp_path / "logs",
                       env={"BUDDYBOT_STATE_DIR": str(tmp_path / "state")})
        started.append(proc)
        return proc

    yield start
    stop_and_report(started, tail=3000)


@pytest.fixture
def started(tmp_path: Path) -> Iterator[Callable[..., Process]]:
    """Start processes (logs in tmp_path/logs); all stopped, and their output shown,
    at the end of the test."""
    procs: list[Process] = []

    def start(argv: list[str], name: str) -> Process:
        proc = Process(argv, name, tmp_path / "logs")
        procs.append(proc)
        return proc

    yield start
    stop_and_report(procs, tail=3000)
