"""scripts/make-test-certs.sh: a CA and per-host certificates that openssl accepts."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.deploy.conftest import CERT_SCRIPT, HOSTS, make_certs

pytestmark = pytest.mark.integration  # runs the certificate script and openssl


def openssl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["openssl", *args], capture_output=True, text=True, timeout=60,
                          check=False)


def subject_cn(cert: Path) -> str:
    done = openssl("x509", "-in", str(cert), "-noout", "-subject", "-nameopt", "multiline")
    line = next(ln for ln in done.stdout.splitlines() if "commonName" in ln)
    return line.split("=", 1)[1].strip()


def extensions(cert: Path) -> str:
    return openssl("x509", "-in", str(cert), "-noout", "-text").stdout


@pytest.mark.parametrize("host", HOSTS)
def test_each_host_certificate_carries_its_name_and_is_signed_by_the_ca(
    cert_dir: Path, host: str
) -> None:
    cert = cert_dir / f"{host}.pem"
    assert subject_cn(cert) == host
    verified = openssl("verify", "-CAfile", str(cert_dir / "ca.pem"), str(cert))
    assert verified.returncode == 0, verified.stdout + verified.stderr
    assert "TLS Web Client Authentication" in extensions(cert)
    key_mode = (cert_dir / f"{host}.key").stat().st_mode & 0o777
    assert key_mode == 0o600, "private keys must not be readable by others"


def test_router_certificate_names_loopback(cert_dir: Path) -> None:
    text = extensions(cert_dir / "router.pem")
    assert "TLS Web Server Authentication" in text
    assert "DNS:localhost" in text and "IP Address:127.0.0.1" in text
    assert subject_cn(cert_dir / "router.pem") == "router"


def test_router_names_given_on_the_command_line(tmp_path: Path) -> None:
    done = make_certs(tmp_path, "buddy.local", "192.168.1.20")
    assert done.returncode == 0, done.stderr
    text = extensions(tmp_path / "router.pem")
    assert "DNS:buddy.local" in text and "IP Address:192.168.1.20" in text


def test_rogue_certificate_has_a_real_name_but_the_wrong_signer(cert_dir: Path) -> None:
    assert subject_cn(cert_dir / "rogue.pem") == "robot"
    refused = openssl("verify", "-CAfile", str(cert_dir / "ca.pem"), str(cert_dir / "rogue.pem"))
    assert refused.returncode != 0


def test_ca_is_a_ca_and_hosts_are_not(cert_dir: Path) -> None:
    assert "CA:TRUE" in extensions(cert_dir / "ca.pem")
    assert "CA:FALSE" in extensions(cert_dir / "robot.pem")


@pytest.mark.parametrize("args", [[], ["--help"]])
def test_usage(tmp_path: Path, args: list[str]) -> None:
    done = subprocess.run(["bash", str(CERT_SCRIPT), *args], capture_output=True, text=True,
                          timeout=60, check=False, cwd=tmp_path)
    assert "OUTDIR" in done.stdout
    assert done.returncode == (0 if args else 2)


def test_bad_router_name_is_refused(tmp_path: Path) -> None:
    done = make_certs(tmp_path / "out", "bad name;rm")
    assert done.returncode == 2
    assert "not a host name" in done.stderr
