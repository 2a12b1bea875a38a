"""deploy/kits/: one robot config per kit of parts in docs/hardware.md.

Each file is checked the way a builder checks it, `buddybot config --config
FILE` in a process of its own (exit 0, the effective values as JSON), and
then for what makes it that kit: the USB kit reads serial devices, the ESP32
kit the host and ports of deploy/esphome/radar-esp32.yaml, the LD2450 kit
says its model, places the sensor and has zones. A broken copy of each is
refused with the key named, so the check is one that can fail. No router,
no network: `config` only reads the file (those tests are marked integration
for the process they start; the loader's own check of each kit runs in the
quick suite too).
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from buddybot.runtime.config import load_config
from buddybot.tools.testing import buddybot_argv
from tests.deploy.conftest import DEPLOY

KITS = DEPLOY / "kits"
HARDWARE = Path(__file__).resolve().parents[2] / "docs" / "hardware.md"
ESPHOME = DEPLOY / "esphome" / "radar-esp32.yaml"
EXPECTED = {"n100-usb-radars.toml", "pi5-esp32-radars.toml", "ld2450-robot.toml"}
MODELS = {"LD2410", "LD2450"}


def config(path: Path) -> subprocess.CompletedProcess[str]:
    """`buddybot config --config PATH --json`, run from elsewhere (no local file helps)."""
    return subprocess.run(buddybot_argv("config", "--config", str(path), "--json"),
                          cwd=path.parent, capture_output=True, text=True, timeout=60,
                          check=False)


def effective(path: Path) -> dict[str, Any]:
    done = config(path)
    assert done.returncode == 0, f"{path.name}: {done.stderr}"
    parsed: dict[str, Any] = json.loads(done.stdout)
    return parsed


def test_the_kits_are_the_ones_docs_hardware_names() -> None:
    assert {p.name for p in KITS.glob("*.toml")} == EXPECTED
    doc = HARDWARE.read_text()
    for name in EXPECTED:
        assert f"deploy/kits/{name}" in doc, f"docs/hardware.md does not name {name}"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_config_loader_accepts_the_kit(name: str) -> None:
    """In process, for the quick suite: the same loader every service uses."""
    cfg = load_config(str(KITS / name))
    assert cfg.radar_bridge.sensors and cfg.face_detector.hfov_deg


@pytest.mark.integration
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_buddybot_config_accepts_the_kit(name: str) -> None:
    cfg = effective(KITS / name)
    bridge = cfg["radar_bridge"]
    assert bridge["sensors"], "a kit has radars"
    assert bridge["baudrate"] == 256000
    assert set(bridge["models"].values()) <= MODELS
    assert all(int(i) < len(bridge["sensors"]) for i in bridge["models"])
    assert all(m["sensor"] < len(bridge["sensors"]) for m in bridge["mount"])
    assert not bridge["sim"] and not cfg["camera"]["sim"], "a kit is real hardware"
    assert cfg["camera"]["source"] != ""
    assert cfg["face_detector"]["hfov_deg"], "the camera's field of view gives distances"
    assert cfg["audio_player"]["backend"] == "alsa" and cfg["audio_player"]["device"]
    eyes = cfg["eye_renderer"]
    assert eyes["left_display"] >= 1 and eyes["right_display"] >= 1


@pytest.mark.integration
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_broken_kit_is_refused_naming_the_key(name: str, tmp_path: Path) -> None:
    text = (KITS / name).read_text()
    broken = tmp_path / name
    broken.write_text(text.replace("range_m = ", "range_mm = ", 1))
    done = config(broken)
    assert done.returncode == 2 and "range_mm" in done.stderr, done.stderr


@pytest.mark.integration
def test_the_usb_kit_reads_two_serial_devices_on_two_screens() -> None:
    cfg = effective(KITS / "n100-usb-radars.toml")
    sensors = cfg["radar_bridge"]["sensors"]
    assert len(sensors) == 2 and all(s.startswith("/dev/") for s in sensors)
    eyes = cfg["eye_renderer"]
    assert eyes["left_display"] != eyes["right_display"]


@pytest.mark.integration
def test_the_esp32_kit_reads_the_esp32_files_ports() -> None:
    cfg = effective(KITS / "pi5-esp32-radars.toml")
    esp = yaml.safe_load(re.sub(r"!secret \w+", "x", ESPHOME.read_text()))
    subs = esp["substitutions"]
    expected = [f"socket://{subs['name']}.local:{subs[f'radar{i}_port']}" for i in (0, 1)]
    assert cfg["radar_bridge"]["sensors"] == expected


@pytest.mark.integration
def test_the_ld2450_kit_places_its_radar_and_has_zones() -> None:
    cfg = effective(KITS / "ld2450-robot.toml")
    bridge = cfg["radar_bridge"]
    assert bridge["models"] == {"0": "LD2450"}
    assert [m["sensor"] for m in bridge["mount"]] == [0]
    zones = cfg["radar_presence"]["zones"]
    assert {z["mode"] for z in zones} == {"detect", "ignore"}
    eyes = cfg["eye_renderer"]
    assert eyes["left_display"] == eyes["right_display"], "one screen shows both eyes"
