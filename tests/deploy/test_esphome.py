"""deploy/esphome/: the ESP32 configuration that forwards two radars over TCP.

Pure (PyYAML only): the file's structure (two UARTs at 256000 8N1, pins
distinct and none to avoid, one stream server per UART on its own port, the
component pinned to a commit), its secrets against secrets.yaml.example and
its pins against the wiring table of docs/esp32-radar.md.

Marked integration (starts `esphome`): ESPHome's own `esphome config` on the
file, with the stream server component taken from a local stand-in
(esphome_standin/) since fetching the real one needs the network. Skipped,
saying so, where ESPHome is not installed: it is not a test dependency
(~250 MB with PlatformIO). Point BUDDYBOT_ESPHOME at an `esphome` executable
or put one on PATH.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "deploy" / "esphome"
CONFIG = FOLDER / "radar-esp32.yaml"
SECRETS = FOLDER / "secrets.yaml.example"
DOC = ROOT / "docs" / "esp32-radar.md"
STANDIN = Path(__file__).resolve().parent / "esphome_standin"
SUBST = re.compile(r"\$\{(\w+)\}|\$(\w+)")

FLASH = {6, 7, 8, 9, 10, 11}
CONSOLE = {1, 3}
STRAPPING = {0, 2, 5, 12, 15}
PSRAM = {16, 17}  # WROVER modules
INPUT_ONLY = set(range(34, 40))
ESPHOME_PORTS = {6053, 3232}  # native API, OTA


class Secret(str):
    """A `!secret NAME` value: its name."""


class Loader(yaml.SafeLoader):
    """ESPHome YAML: `!secret` tags kept as names."""


Loader.add_constructor("!secret", lambda loader, node: Secret(loader.construct_scalar(node)))


def load(path: Path = CONFIG, **overrides: str) -> dict[str, Any]:
    """The config with its substitutions applied, as ESPHome applies them."""
    raw = yaml.load(path.read_text(), Loader=Loader)  # a SafeLoader: no arbitrary objects
    subs = {k: str(v) for k, v in raw.pop("substitutions", {}).items()} | overrides

    def apply(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: apply(v) for k, v in value.items()}
        if isinstance(value, list):
            return [apply(v) for v in value]
        if isinstance(value, str) and not isinstance(value, Secret):
            return SUBST.sub(lambda m: subs[m.group(1) or m.group(2)], value)
        return value

    return apply(raw)


def gpio(pin: Any) -> int:
    text = pin["number"] if isinstance(pin, dict) else pin
    match = re.fullmatch(r"GPIO(\d+)", str(text))
    assert match, f"pin {text!r}: write pins as GPIOn"
    return int(match.group(1))


def secrets_used(value: Any) -> set[str]:
    if isinstance(value, dict):
        return set().union(*(secrets_used(v) for v in value.values()))
    if isinstance(value, list):
        return set().union(*(secrets_used(v) for v in value))
    return {str(value)} if isinstance(value, Secret) else set()


def pin_problems(cfg: dict[str, Any]) -> list[str]:
    """What is wrong with the UARTs' pins on a classic ESP32 (empty: nothing)."""
    problems = []
    seen: dict[int, str] = {}
    for uart in cfg["uart"]:
        for role in ("rx_pin", "tx_pin"):
            n = gpio(uart[role])
            where = f"{uart['id']}.{role} GPIO{n}"
            if n in seen:
                problems.append(f"{where} is also {seen[n]}")
            seen[n] = where
            for bad, why in ((FLASH, "the SPI flash"), (CONSOLE, "UART0, the USB console"),
                             (STRAPPING, "a strapping pin"), (PSRAM, "PSRAM on WROVER")):
                if n in bad:
                    problems.append(f"{where} is {why}")
            if role == "tx_pin" and n in INPUT_ONLY:
                problems.append(f"{where} is input only")
    return problems


def test_two_uarts_at_the_radars_factory_settings() -> None:
    uarts = load()["uart"]
    assert len(uarts) == 2
    for uart in uarts:
        assert int(uart["baud_rate"]) == 256000
        assert (uart["data_bits"], uart["parity"], uart["stop_bits"]) == (8, "NONE", 1)
        assert int(uart["rx_buffer_size"]) >= 512  # > 100 ms of reports
    assert pin_problems(load()) == []


@pytest.mark.parametrize(("override", "found"), [
    ({"radar1_rx_pin": "GPIO25"}, "is also radar0_uart.rx_pin"),
    ({"radar0_tx_pin": "GPIO7"}, "the SPI flash"),
    ({"radar0_rx_pin": "GPIO12"}, "a strapping pin"),
    ({"radar1_tx_pin": "GPIO35"}, "input only"),
    ({"radar1_tx_pin": "GPIO1"}, "USB console"),
])
def test_a_bad_pin_is_caught(override: dict[str, str], found: str) -> None:
    assert any(found in p for p in pin_problems(load(**override))), pin_problems(load(**override))


def test_one_stream_server_per_uart_on_its_own_port() -> None:
    cfg = load()
    servers = cfg["stream_server"]
    uart_ids = [u["id"] for u in cfg["uart"]]
    assert sorted(s["uart_id"] for s in servers) == sorted(uart_ids)
    ports = [int(s["port"]) for s in servers]
    assert len(set(ports)) == len(ports) and not set(ports) & ESPHOME_PORTS
    assert all(1024 <= p <= 65535 for p in ports)
    for s in servers:
        size = int(s["buffer_size"])
        assert size >= 256 and size & (size - 1) == 0  # the component wants a power of two


def test_the_stream_server_component_is_pinned_to_a_commit() -> None:
    [component] = load()["external_components"]
    assert component["components"] == ["stream_server"]
    assert re.fullmatch(r"github://oxan/esphome-stream-server@[0-9a-f]{40}",
                        component["source"]), component["source"]
    commit = component["source"].rpartition("@")[2]
    assert commit in DOC.read_text()


def test_secrets_are_all_in_the_example_and_none_inline() -> None:
    cfg = load()
    example = yaml.safe_load(SECRETS.read_text())
    assert secrets_used(cfg) == set(example)
    assert isinstance(cfg["wifi"]["password"], Secret)
    assert isinstance(cfg["api"]["encryption"]["key"], Secret)
    assert isinstance(cfg["ota"][0]["password"], Secret)
    assert "secrets.yaml" in (FOLDER / ".gitignore").read_text().split()


def test_the_wiring_table_and_the_bridge_urls_match_the_file() -> None:
    cfg = load()
    doc = DOC.read_text()
    table = dict(re.findall(r"\| GPIO(\d+) \| `(\w+)` \|", doc))
    subs = yaml.load(CONFIG.read_text(), Loader=Loader)["substitutions"]
    assert {name: f"GPIO{n}" for n, name in table.items()} == {
        k: v for k, v in subs.items() if k.endswith("_pin")}
    host = cfg["esphome"]["name"]
    for server in cfg["stream_server"]:
        url = f"socket://{host}.local:{server['port']}"
        assert url in doc and url in CONFIG.read_text()


def esphome_command() -> str | None:
    return os.environ.get("BUDDYBOT_ESPHOME") or shutil.which("esphome")


def esphome_config(tmp_path: Path, *subs: str) -> subprocess.CompletedProcess[str]:
    """`esphome config` on a copy of the file (secrets from the example), offline."""
    command = esphome_command()
    if command is None:
        pytest.skip("ESPHome is not installed (not a test dependency: ~250 MB); "
                    "`pip install esphome` in any venv and set BUDDYBOT_ESPHOME to run it")
    shutil.copy(CONFIG, tmp_path / CONFIG.name)
    shutil.copy(SECRETS, tmp_path / "secrets.yaml")
    argv = [command, "-s", "stream_server_source", str(STANDIN)]
    for pair in subs:
        argv += ["-s", *pair.split("=", 1)]
    return subprocess.run([*argv, "config", CONFIG.name], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120, check=False)


@pytest.mark.integration
def test_esphome_accepts_the_file_without_a_warning(tmp_path: Path) -> None:
    done = esphome_config(tmp_path)
    out = done.stdout + done.stderr
    assert done.returncode == 0 and "Configuration is valid!" in out, out
    assert "WARNING" not in out, out
    assert "port: 4001" in out and "baud_rate: 256000" in out


@pytest.mark.integration
@pytest.mark.parametrize(("sub", "said"), [
    ("radar0_tx_pin=GPIO7", "Failed config"),      # the SPI flash: refused
    ("radar0_rx_pin=GPIO12", "strapping PIN"),      # warned
])
def test_esphome_itself_catches_a_bad_pin(tmp_path: Path, sub: str, said: str) -> None:
    """The check above can fail: ESPHome knows the ESP32's pins."""
    done = esphome_config(tmp_path, sub)
    assert said in done.stdout + done.stderr
