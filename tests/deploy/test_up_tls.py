"""`buddybot up` with the shipped TLS files, as the robot computer runs it.

`[zenoh] router_config_file` gives the router `up` starts its own file (the
shipped router.json5: listen certificate, mutual TLS, access control) while
the services and probes use `config_file` (the shipped robot.json5: the robot
computer's client certificate). The live-parameter and introspection services
must pass the access control too.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from buddybot.tools.testing import LOOPBACK, Process, buddybot_argv, free_port
from tests.deploy.conftest import HostProfile
from tests.supervisor.test_launch import reaped

pytestmark = pytest.mark.integration


def _robot_toml(profile: HostProfile, port: int) -> Path:
    path = profile.work / "robot.toml"
    path.write_text(f'[zenoh]\nconnect = ["tls/{LOOPBACK}:{port}"]\n'
                    f'config_file = "{profile.zenoh_file("robot")}"\n'
                    f'router_config_file = "{profile.zenoh_file("router")}"\n')
    return path


def test_up_uses_the_shipped_router_and_robot_files(profile: HostProfile,
                                                    tmp_path: Path) -> None:
    port = free_port()
    config = _robot_toml(profile, port)
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--only", "radar-presence", "--only", "controller",
                               "--status-period", "1"), "up-tls-split", tmp_path)
    with reaped(up):
        up.wait_for_output("nodes 2/2", 120)
        assert f"starting router on tls/{LOOPBACK}:{port}" in up.output()
        # The robot identity may read and set live parameters through the ACL...
        param = subprocess.run(buddybot_argv("param", "get", "radar-presence", "range_m",
                                             "--config", str(config), "--timeout", "10"),
                               capture_output=True, text=True, timeout=60, check=False)
        assert param.returncode == 0, param.stderr
        assert param.stdout.strip().splitlines()[-1] == "2.0"  # the default range
        # ...and ask a node what it declared.
        info = subprocess.run(buddybot_argv("node", "info", "controller", "--config",
                                            str(config), "--timeout", "10", "--json"),
                              capture_output=True, text=True, timeout=60, check=False)
        assert info.returncode == 0, info.stderr
        line = next(t for t in reversed(info.stdout.splitlines()) if t.startswith("{"))
        declared = json.loads(line)["info"]
        assert any(k.endswith("controller/expression") for k in declared["publishers"]), declared
