"""Which services and apps a config runs (`runtime/enabled.py`): the one rule `up`
starts by, doctor expects by and the dashboard keeps listing by."""

from __future__ import annotations

from buddybot.runtime import enabled, registry
from buddybot.runtime.config import default_config, parse_config

ON_REQUEST = {"foxglove", "identity", "ros2-bridge"}


def names(config_text: bytes, *, sim: bool = False) -> set[str]:
    config = parse_config(config_text, "robot.toml")
    return {e.name for e in enabled.enabled_services(config, registry.SERVICES, sim=sim)}


def test_on_request_services_run_only_when_their_table_enables_them() -> None:
    assert not names(b"") & ON_REQUEST
    assert names(b"[identity]\nenabled = true\n") & ON_REQUEST == {"identity"}
    assert names(b"[ros2]\nenabled = true\n") & ON_REQUEST == {"ros2-bridge"}


def test_the_simulated_world_runs_only_with_a_simulated_sensor() -> None:
    hardware = b'[radar_bridge]\nsensors = ["/dev/ttyUSB0"]\n[camera]\nsource = "/dev/video0"\n'
    assert "sim" in names(b"")
    assert "sim" not in names(hardware)
    assert "sim" in names(hardware, sim=True)
    assert "sim" in names(b'[radar_bridge]\nsensors = ["/dev/ttyUSB0"]\n')  # camera simulated


def test_node_names_are_the_services_and_the_apps() -> None:
    config = parse_config(b'[apps]\nrun = ["examples/apps/greeter.py"]\n', "robot.toml")
    nodes = enabled.node_names(config, registry.SERVICES)
    assert "greeter" in nodes and "camera" in nodes and "foxglove" not in nodes
    assert enabled.node_names(default_config(), []) == frozenset()
