"""The shipped deployment files: systemd units, example config, Zenoh profiles.

No processes here: these tests read the files the way systemd, BuddyBot and Zenoh
would, and check they agree with each other and with the service registry.
"""

from __future__ import annotations

import configparser
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.runtime import registry
from buddybot.runtime.config import load_config, parse_config
from buddybot.runtime.errors import ConfigError
from tests.deploy.conftest import DEPLOY, HOSTS, INSTALLED_CERTS, SYSTEMD_DIR, ZENOH_DIR

INSTALLED_BIN = "/opt/buddybot/.venv/bin/buddybot"
ENV_FILE = "/etc/buddybot/env"
SERVICE_NAMES = [e.name for e in registry.SERVICES if not e.simulation]
"""The services of a deployed robot (the simulated world's `sim` runs only under `up`)."""


def unit(path: Path) -> configparser.ConfigParser:
    """A unit file as sections of keys (systemd's syntax is close enough to INI)."""
    parser = configparser.ConfigParser(strict=False, interpolation=None,
                                       comment_prefixes=("#", ";"))
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read_string(path.read_text())
    return parser


def service_units() -> list[Path]:
    return sorted(SYSTEMD_DIR.glob("*.service"))


def env_assignments() -> dict[str, str]:
    """Active `NAME=value` lines of deploy/systemd/env (the file /etc/buddybot/env)."""
    found: dict[str, str] = {}
    for line in (SYSTEMD_DIR / "env").read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            name, _, value = line.partition("=")
            found[name.strip()] = value
    return found


# --- example config ----------------------------------------------------------------


def test_example_robot_config_parses() -> None:
    config = load_config(str(DEPLOY / "robot.toml"))
    assert keys.valid_robot_id(config.robot.id)
    assert config.zenoh.connect, "the example must say where the router is"
    assert config.radar_presence.range_m == pytest.approx(2.0)
    assert set(config.audio.sounds) >= {"greeting", "farewell"}


def test_example_config_with_a_typo_is_refused() -> None:
    """The example is really checked: the same text with a misspelt key is an error."""
    text = (DEPLOY / "robot.toml").read_text().replace("range_m = ", "range_mm = ", 1)
    with pytest.raises(ConfigError, match="range_mm"):
        parse_config(text, "robot.toml")


def test_commented_multi_host_settings_parse() -> None:
    """Each commented [zenoh] line for several hosts is valid once uncommented."""
    text = (DEPLOY / "robot.toml").read_text()
    block = text[text.index("[zenoh]"):text.index("[radar_bridge]")]
    commented = re.findall(r"^# ((?:connect|config_file) = .+)$", block, re.M)
    assert len(commented) >= 4
    for line in commented:
        config = parse_config(f"[zenoh]\n{line}\n", "robot.toml")
        if line.startswith("connect"):
            assert all(ep.startswith("tls/") for ep in config.zenoh.connect), line
        else:
            assert config.zenoh.config_file is not None
            name = Path(config.zenoh.config_file).name
            assert (ZENOH_DIR / name).is_file(), f"{line}: no deploy/zenoh/{name}"


# --- systemd -----------------------------------------------------------------------


def test_one_unit_per_service_plus_router_and_target() -> None:
    names = {p.name for p in SYSTEMD_DIR.iterdir()}
    expected = {f"buddybot-{s}.service" for s in SERVICE_NAMES} | {
        "buddybot-router.service", "buddybot.target", "env"}
    assert names == expected


@pytest.mark.parametrize("path", service_units(), ids=lambda p: p.stem)
def test_unit_runs_a_real_buddybot_verb(path: Path) -> None:
    service = unit(path)["Service"]
    argv = shlex.split(service["ExecStart"])
    assert argv[0] == INSTALLED_BIN
    from buddybot.cli import build_parser

    if path.stem == "buddybot-router":
        assert argv[1] == "router"
        build_parser().parse_args(["router", "--listen", "tcp/127.0.0.1:7447"])
        return
    assert argv[1] == "run", path.name
    name = argv[2]
    assert name in SERVICE_NAMES, f"{path.name}: no service {name!r} in the registry"
    assert path.stem == f"buddybot-{name}"
    entry = registry.service(name)
    assert entry is not None and entry.exists(), f"{entry} is not installed"
    # The command line systemd would build parses (the extra-args variable empty).
    args = build_parser().parse_args(argv[1:3])
    assert args.service == name


@pytest.mark.parametrize("path", service_units(), ids=lambda p: p.stem)
def test_unit_restarts_on_failure_and_reads_the_one_env_file(path: Path) -> None:
    parsed = unit(path)
    service = parsed["Service"]
    assert service["Restart"] == "on-failure"
    assert service["EnvironmentFile"] == ENV_FILE
    # The config path is set in the env file only, never per unit.
    assert "BUDDYBOT_CONFIG" not in service.get("Environment", "")
    assert "robot.toml" not in path.read_text()
    assert "--config" not in service["ExecStart"]
    assert parsed["Unit"]["PartOf"] == "buddybot.target"
    assert parsed["Install"]["WantedBy"] == "buddybot.target"
    # Its extra-arguments variable is documented in the env file.
    variables = re.findall(r"\$\{?(\w+)\}?", service["ExecStart"])
    env_text = (SYSTEMD_DIR / "env").read_text()
    for var in variables:
        assert re.search(rf"^#?{var}=", env_text, re.M), f"{var} not in deploy/systemd/env"


@pytest.mark.parametrize("path", service_units(), ids=lambda p: p.stem)
def test_unit_sets_its_descriptor_limit(path: Path) -> None:
    """`LimitNOFILE` in every unit: the web surfaces size their connection caps
    from it (web/guard.py), and none runs on an unstated default."""
    limit = unit(path)["Service"].get("LimitNOFILE", "")
    assert limit.isdigit() and int(limit) >= 1024, f"{path.name}: LimitNOFILE={limit!r}"
    web = {"buddybot-dashboard", "buddybot-eye-renderer", "buddybot-foxglove"}
    if path.stem in web:
        assert int(limit) >= 4096


def test_env_file_names_the_config_and_the_router() -> None:
    env = env_assignments()
    assert env["BUDDYBOT_CONFIG"] == "/etc/buddybot/robot.toml"
    assert "--listen" in env["BUDDYBOT_ROUTER_ARGS"]
    assert "127.0.0.1" in env["BUDDYBOT_ROUTER_ARGS"], "one host by default: loopback only"


def test_target_is_wanted_at_boot() -> None:
    assert unit(SYSTEMD_DIR / "buddybot.target")["Install"]["WantedBy"] == "multi-user.target"


@pytest.mark.integration
@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze")
def test_systemd_analyze_verify(tmp_path: Path) -> None:
    """systemd's own checker, with ExecStart pointed at this checkout's buddybot."""
    here = Path(sys.executable).parent / "buddybot"
    if not here.exists():
        pytest.skip("buddybot console script not installed next to this Python")
    for path in SYSTEMD_DIR.iterdir():
        if path.suffix in (".service", ".target"):
            (tmp_path / path.name).write_text(path.read_text().replace(INSTALLED_BIN, str(here)))
    files = sorted(str(p) for p in tmp_path.iterdir())
    done = subprocess.run(["systemd-analyze", "verify", *files],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0 and not done.stderr.strip(), done.stderr


MAX_EXPOSURE = 4.0
"""`systemd-analyze security` rates exposure 0 (locked down) .. 10; 8.8 before hardening."""


def exposure(path: Path) -> float:
    """The overall exposure `systemd-analyze security --offline=yes` gives a unit file."""
    done = subprocess.run(["systemd-analyze", "security", "--offline=yes", str(path)],
                          capture_output=True, text=True, timeout=120, check=False)
    found = re.search(r"Overall exposure level for \S+: (\d+(?:\.\d+)?)", done.stdout)
    assert found, f"{path.name}: no exposure in {done.stdout[-500:]!r} {done.stderr[-500:]!r}"
    return float(found.group(1))


@pytest.mark.integration
@pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                    reason="systemd-analyze is not installed (systemd's own rating is the check)")
@pytest.mark.parametrize("path", service_units(), ids=lambda p: p.stem)
def test_unit_is_hardened(path: Path) -> None:
    """systemd's own rating of the sandbox, read from the file alone (offline)."""
    value = exposure(path)
    assert value < MAX_EXPOSURE, f"{path.name}: exposure {value} (must stay below {MAX_EXPOSURE})"


@pytest.mark.parametrize("path", service_units(), ids=lambda p: p.stem)
def test_unit_sandbox_and_notify(path: Path) -> None:
    """The settings the rating alone would let slip: readiness, watchdog, journal name,
    no capabilities, read-only system, devices only where the hardware is."""
    service = unit(path)["Service"]
    name = path.stem.removeprefix("buddybot-")
    assert service["SyslogIdentifier"] == f"buddybot-{name}"
    assert service["Type"] == "notify"
    assert service["NotifyAccess"] == "main"
    assert 0 < int(service["WatchdogSec"]) <= 30
    assert service["Restart"] == "on-failure", "a missed watchdog is a failure: restarted"
    if name != "router":  # services wait for a router that may live elsewhere
        assert service["TimeoutStartSec"] == "infinity"
    assert service["ProtectSystem"] == "strict"
    assert service["ProtectHome"] == "yes"
    assert service["PrivateTmp"] == "yes"
    assert service["NoNewPrivileges"] == "yes"
    assert service["CapabilityBoundingSet"] == ""
    assert service["SystemCallFilter"] == "@system-service"
    assert set(service["RestrictAddressFamilies"].split()) <= {
        "AF_UNIX", "AF_INET", "AF_INET6", "AF_NETLINK"}
    text = path.read_text()
    hardware = {"radar-bridge": ("dialout", "char-tty"), "camera": ("video", "char-video4linux"),
                "audio-player": ("audio", "char-alsa")}
    if name in hardware:
        group, device = hardware[name]
        assert service["SupplementaryGroups"] == group
        assert service["DevicePolicy"] == "closed"
        assert re.search(rf"^DeviceAllow={device}\S* rw$", text, re.M), f"{path.name}: {device}"
    else:
        assert service["PrivateDevices"] == "yes"
        assert "SupplementaryGroups" not in service
        assert "DeviceAllow" not in service


# --- Zenoh profiles ----------------------------------------------------------------


def zenoh_json(name: str, path: str) -> object:
    """A value of a deploy Zenoh file as Zenoh itself parsed it."""
    return json.loads(zenoh.Config.from_file(str(ZENOH_DIR / name)).get_json(path))


@pytest.mark.parametrize("name", sorted(p.name for p in ZENOH_DIR.glob("*.json5")))
def test_zenoh_file_is_accepted_by_zenoh(name: str) -> None:
    """Zenoh rejects unknown fields and bad values, so this catches typos."""
    zenoh.Config.from_file(str(ZENOH_DIR / name))
    assert zenoh_json(name, "transport/link/protocols") == ["tls"]
    tls = zenoh_json(name, "transport/link/tls")
    assert isinstance(tls, dict)
    assert tls["enable_mtls"] is True
    assert tls["root_ca_certificate"] == INSTALLED_CERTS + "ca.pem"


@pytest.mark.parametrize("host", HOSTS)
def test_client_file_uses_its_own_certificate(host: str) -> None:
    tls = zenoh_json(f"{host}.json5", "transport/link/tls")
    assert isinstance(tls, dict)
    assert tls["connect_certificate"] == f"{INSTALLED_CERTS}{host}.pem"
    assert tls["connect_private_key"] == f"{INSTALLED_CERTS}{host}.key"
    assert tls["verify_name_on_connect"] is True
    assert tls["listen_private_key"] is None, "a client does not listen"


def test_router_access_control_is_default_deny_and_consistent() -> None:
    acl = zenoh_json("router.json5", "access_control")
    assert isinstance(acl, dict)
    assert acl["enabled"] is True
    assert acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s for s in acl["subjects"]}
    used_rules = {r for p in acl["policies"] for r in p["rules"]}
    used_subjects = {s for p in acl["policies"] for s in p["subjects"]}
    assert used_rules == set(rules), "a rule is unused or a policy names a missing rule"
    assert used_subjects == set(subjects)
    # Identities are certificate common names, one per host with a client file.
    assert {cn for s in subjects.values() for cn in s["cert_common_names"]} == set(HOSTS)
    for rule in rules.values():
        assert rule["permission"] == "allow", "default deny: only grants are needed"
        assert rule["flows"], f"{rule['id']}: say ingress or egress, not both by omission"
        for key in rule["key_exprs"]:
            if rule["id"] in ROS2_RULES:
                assert key in ("0/**", "0/**/@adv/**", "@ros2_lv/0/**"), f"{rule['id']}: {key}"
            else:
                assert key.startswith("buddybot/buddy/"), f"{rule['id']}: {key} leaves the robot"


ROS2_RULES = ("robot-ros2-write-ask", "robot-ros2-receive")
"""The only grants outside the robot prefix: rmw_zenoh's keys of ROS domain 0."""


def test_only_the_robot_computer_speaks_ros_2() -> None:
    acl = zenoh_json("router.json5", "access_control")
    assert isinstance(acl, dict)
    holders = {tuple(p["subjects"]) for p in acl["policies"]
               if set(ROS2_RULES) & set(p["rules"])}
    assert holders == {("robot",)}


def test_no_host_may_publish_everywhere() -> None:
    """Ingress puts are granted on named keys, never on the whole robot."""
    acl = zenoh_json("router.json5", "access_control")
    assert isinstance(acl, dict)
    for rule in acl["rules"]:
        if "ingress" in rule["flows"] and "put" in rule["messages"]:
            for key in rule["key_exprs"]:
                assert not key.endswith("buddy/**"), f"{rule['id']} grants puts on {key}"


def test_operator_is_read_only() -> None:
    acl = zenoh_json("router.json5", "access_control")
    assert isinstance(acl, dict)
    rules = {r["id"]: r for r in acl["rules"]}
    for policy in acl["policies"]:
        if policy["subjects"] == ["operator"]:
            for rid in policy["rules"]:
                rule = rules[rid]
                assert not ("ingress" in rule["flows"] and
                            {"put", "delete", "declare_queryable"} & set(rule["messages"]))
