"""`buddybot doctor`'s checks on crafted inputs: no robot, no processes."""

from __future__ import annotations

import json
import socket

import pytest

from buddybot.runtime.config import default_config, parse_config
from buddybot.runtime.errors import ConfigError
from buddybot.tools import doctor
from buddybot.tools.doctor import FAIL, OK, WARN, Check


def test_report_is_one_line_per_check_and_a_summary() -> None:
    checks = [Check("router", OK, "reachable"), Check("nodes", FAIL, "missing: camera"),
              Check("audio device", WARN, "null backend")]
    text = doctor.format_report(checks)
    lines = text.splitlines()
    assert len(lines) == 4
    assert lines[0].split() == ["OK", "router", "reachable"]
    assert lines[1].startswith("FAIL  nodes ") and lines[1].endswith("missing: camera")
    assert lines[3] == ("doctor: 1 ok, 1 warn, 1 fail: nodes (FAIL), audio device (WARN)")
    assert doctor.exit_code(checks) == 1
    assert doctor.exit_code(checks[::2]) == 0  # warnings are not failures
    data = json.loads(doctor.to_json(checks))
    assert data["ok"] is False
    assert data["checks"][1] == {"name": "nodes", "level": "FAIL", "detail": "missing: camera"}


def test_config_error_is_reported_with_its_line() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(b"[camera]\nfps = -3\n", "robot.toml")
    check = doctor.judge_config(None, str(caught.value))
    assert check.level == FAIL and "robot.toml" in check.detail and "fps" in check.detail
    assert doctor.judge_config(default_config(), None).level == OK


def test_nodes_missing_fail_duplicates_warn() -> None:
    live = {"camera": {"a"}, "eyes": {"b", "c"}, "extra": {"d"}}
    missing = doctor.judge_nodes(["camera", "controller"], live)
    assert missing.level == FAIL and missing.detail == "1/2 alive; missing: controller"
    dupes = doctor.judge_nodes(["camera", "eyes"], live)
    assert dupes.level == WARN and "eyes" in dupes.detail
    assert doctor.judge_nodes(["camera"], live).level == WARN  # any duplicate is suspect
    fine = doctor.judge_nodes(["camera"], {"camera": {"a"}, "extra": {"d"}})
    assert fine.level == OK and fine.detail == "1/1 alive (also: extra)"


def test_rates_against_what_is_expected() -> None:
    assert doctor.judge_rate("radar frames", 20, 2.0, 10.0).level == OK
    slow = doctor.judge_rate("camera images", 10, 2.0, 30.0)
    assert slow.level == WARN and "5.0 Hz" in slow.detail
    silent = doctor.judge_rate("camera images", 0, 2.0, 30.0)
    assert silent.level == FAIL and "nothing received" in silent.detail


def test_clock() -> None:
    now = 1_800_000_000.0
    assert doctor.judge_clock(now, 5.0, 5.1).level == OK
    assert doctor.judge_clock(1_500_000_000.0, 5.0, 5.1).level == FAIL  # 2017: never set
    assert doctor.judge_clock(now, 5.0, 4.9).level == FAIL
    near = doctor.judge_clock(now, 5.0, 5.1, stamp_ns=int((now - 0.05) * 1e9))
    assert near.level == OK and "+50 ms" in near.detail
    skewed = doctor.judge_clock(now, 5.0, 5.1, stamp_ns=int((now - 30) * 1e9))
    assert skewed.level == WARN and "+30.0 s" in skewed.detail


def test_router_and_port_verdicts() -> None:
    ok = doctor.judge_router("tls/127.0.0.1:7447", True)
    assert ok.level == OK and "transport tls" in ok.detail
    down = doctor.judge_router("tcp/127.0.0.1:7447", False, "no router. Retry in 500ms.")
    assert down.level == FAIL and down.detail.endswith("no router")
    assert doctor.judge_port("tcp/127.0.0.1:7447", False, None).level == OK
    stranger = doctor.judge_port("tcp/127.0.0.1:7447", True, None)
    assert stranger.level == FAIL and "not a Zenoh router" in stranger.detail
    ours = doctor.judge_port("tcp/127.0.0.1:7447", True, ["buddy/camera"])
    assert ours.level == OK and "buddy/camera" in ours.detail


def test_versions_name_what_is_missing() -> None:
    found = doctor.versions()
    assert found["python"] and found["zenoh"] and found["msgspec"]
    check = doctor.judge_versions({"python": "3.11.7", "ai-edge-litert": None})
    assert check.level == WARN and "ai-edge-litert MISSING" in check.detail


def test_display_down_is_a_failure_not_a_hang() -> None:
    with socket.socket() as holder:  # a port we know nobody serves: bound, not listening
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        check = doctor.check_display("0.0.0.0", port, timeout=1.0)
    assert check.level == FAIL and f"http://127.0.0.1:{port}/healthz" in check.detail


def test_quick_checks_need_no_robot() -> None:
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        opts = doctor.Options(sim=True, endpoint=f"tcp/127.0.0.1:{port}")
        checks = doctor.quick_checks(default_config(), None, opts)
    names = [c.name for c in checks]
    assert names[0] == "config" and "versions" in names and names[-1] == "router port"
    assert checks[-1].level == OK and "is free" in checks[-1].detail
    broken = doctor.quick_checks(None, "robot.toml: bad", opts, port=False)
    assert broken[0] == Check("config", FAIL, "robot.toml: bad")


def test_the_services_lend_their_checks_in_the_registry_order() -> None:
    """Radar, camera and audio checks come from their areas, in the report's order."""
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        opts = doctor.Options(sim=True, endpoint=f"tcp/127.0.0.1:{holder.getsockname()[1]}")
        checks = doctor.quick_checks(default_config(), None, opts)
    assert [c.name for c in checks] == ["config", "radar serial", "camera device",
                                        "audio device", "versions", "router port"]
    assert list(doctor.versions()) == ["python", "buddybot", "zenoh", "msgspec", "numpy",
                                       "opencv", "ai-edge-litert"]
    assert "opencv" in checks[4].detail and "ai-edge-litert" in checks[4].detail
