"""deploy/esphome/: the ESP32 configuration that forwards two radars over TCP.

Pure (PyYAML only): the file's structure (two UARTs at 256000 8N1, pins
distinct and none to avoid on the board's chip, one `serial_tcp` server per
UART on its own port, the component read from this repository's own folder),
its secrets against secrets.yaml.example and its pins against the wiring
table of docs/esp32-radar.md.

Marked integration (starts `esphome`): ESPHome's own `esphome config` on the
real file and its real component, with no network (inside a network
namespace of its own where `unshare -n` works), and the C++ that ESPHome
generates from it; then our component's C++ compiled for syntax against the
headers of the same ESPHome (where g++ exists). Skipped, saying so, where
ESPHome is not installed: it is not a test dependency (~250 MB);
scripts/esphome.sh installs it outside the project's venv and
scripts/test.sh runs it. BUDDYBOT_ESPHOME names an `esphome` executable.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.cache import cache_root

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "deploy" / "esphome"
CONFIG = FOLDER / "radar-esp32.yaml"
SECRETS = FOLDER / "secrets.yaml.example"
COMPONENT = FOLDER / "components" / "serial_tcp"
DOC = ROOT / "docs" / "esp32-radar.md"
INSTALLER = ROOT / "scripts" / "esphome.sh"
SUBST = re.compile(r"\$\{(\w+)\}|\$(\w+)")
ESPHOME_PORTS = {6053, 3232}  # native API, OTA


@dataclass(frozen=True)
class Chip:
    """The pins of one ESP32 family a radar UART must not take, and why."""

    avoid: dict[str, set[int]]
    input_only: frozenset[int] = frozenset()
    exists: frozenset[int] | None = None


CLASSIC = Chip({
    "the SPI flash": set(range(6, 12)),
    "UART0, the USB console": {1, 3},
    "a strapping pin": {0, 2, 5, 12, 15},
    "PSRAM on WROVER": {16, 17},
}, input_only=frozenset(range(34, 40)))
S3 = Chip({
    "the SPI flash and PSRAM": set(range(26, 33)),
    "octal PSRAM on R8 modules": set(range(33, 38)),
    "USB (the log and the flashing port)": {19, 20},
    "UART0, the USB-UART bridge": {43, 44},
    "a strapping pin": {0, 3, 45, 46},
    "the board's RGB LED": {38, 48},
}, exists=frozenset(range(0, 22)) | frozenset(range(26, 49)))


def chip(board: str) -> Chip:
    if "s3" in board.lower():
        return S3
    if board in {"esp32dev", "esp-wrover-kit", "nodemcu-32s"}:
        return CLASSIC
    raise AssertionError(f"board {board!r}: no pin table for its chip in this test")


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
    """What is wrong with the UARTs' pins on the board's chip (empty: nothing)."""
    table = chip(cfg["esp32"]["board"])
    problems = []
    seen: dict[int, str] = {}
    for uart in cfg["uart"]:
        for role in ("rx_pin", "tx_pin"):
            n = gpio(uart[role])
            where = f"{uart['id']}.{role} GPIO{n}"
            if n in seen:
                problems.append(f"{where} is also {seen[n]}")
            seen[n] = where
            if table.exists is not None and n not in table.exists:
                problems.append(f"{where} does not exist on this chip")
            problems += [f"{where} is {why}" for why, pins in table.avoid.items() if n in pins]
            if role == "tx_pin" and n in table.input_only:
                problems.append(f"{where} is input only")
    return problems


def test_two_uarts_at_the_radars_factory_settings() -> None:
    cfg = load()
    assert "s3" in cfg["esp32"]["board"], "docs/hardware.md lists an ESP32-S3 board"
    uarts = cfg["uart"]
    assert len(uarts) == 2
    for uart in uarts:
        assert int(uart["baud_rate"]) == 256000
        assert (uart["data_bits"], uart["parity"], uart["stop_bits"]) == (8, "NONE", 1)
        assert int(uart["rx_buffer_size"]) >= 512  # > 100 ms of reports
    assert pin_problems(cfg) == []


def test_the_classic_esp32_pins_of_the_doc_are_fine_there() -> None:
    """The alternative board docs/esp32-radar.md gives, with its four pins."""
    doc = DOC.read_text()
    classic = doc[doc.index("## A classic ESP32 instead"):]
    table = dict(re.findall(r"\| GPIO(\d+) \| `(\w+)` \|", classic))
    assert len(table) == 4, table
    subs = {name: f"GPIO{n}" for n, name in table.items()}
    assert pin_problems(load(board="esp32dev", **subs)) == []


@pytest.mark.parametrize(("override", "found"), [
    ({"radar1_rx_pin": "GPIO4"}, "is also radar0_uart.rx_pin"),
    ({"radar0_tx_pin": "GPIO27"}, "the SPI flash"),
    ({"radar0_rx_pin": "GPIO45"}, "a strapping pin"),
    ({"radar1_tx_pin": "GPIO20"}, "USB"),
    ({"radar1_tx_pin": "GPIO35"}, "octal PSRAM"),
    ({"radar1_tx_pin": "GPIO23"}, "does not exist"),
    ({"board": "esp32dev", "radar1_tx_pin": "GPIO35"}, "input only"),
    ({"board": "esp32dev", "radar0_tx_pin": "GPIO1"}, "USB console"),
])
def test_a_bad_pin_is_caught(override: dict[str, str], found: str) -> None:
    problems = pin_problems(load(**override))
    assert any(found in p for p in problems), problems


def test_one_server_per_uart_on_its_own_port() -> None:
    cfg = load()
    servers = cfg["serial_tcp"]
    uart_ids = [u["id"] for u in cfg["uart"]]
    assert sorted(s["uart_id"] for s in servers) == sorted(uart_ids)
    ports = [int(s["port"]) for s in servers]
    assert len(set(ports)) == len(ports) and not set(ports) & ESPHOME_PORTS
    assert all(1024 <= p <= 65535 for p in ports)
    for s in servers:
        size = int(s["buffer_size"])
        assert size >= 256 and size & (size - 1) == 0  # the component wants a power of two
        assert s["max_clients"] == 1  # a second reader would mix its commands into the stream


def test_the_component_is_this_repositorys_own() -> None:
    """Nothing is fetched at configuration time: the source is a local folder."""
    [component] = load()["external_components"]
    assert component["source"] == {"type": "local", "path": "components"}
    assert component["components"] == ["serial_tcp"]
    assert (FOLDER / component["source"]["path"] / "serial_tcp").resolve() == COMPONENT
    for name in ("__init__.py", "binary_sensor.py", "serial_tcp.h", "serial_tcp.cpp"):
        assert (COMPONENT / name).is_file(), name
    text = CONFIG.read_text()
    assert "github://" not in text and "type: git" not in text


def test_the_cpp_keeps_its_promises() -> None:
    """Non-blocking sockets, memory fixed at setup, a bounded client table: read
    from the source, since no ESP32 build runs here."""
    cpp = (COMPONENT / "serial_tcp.cpp").read_text()
    header = (COMPONENT / "serial_tcp.h").read_text()
    assert cpp.count("setblocking(false)") == 2  # the listener and every client
    assert "void SerialTcpServer::setup()" in cpp and "void SerialTcpServer::loop()" in cpp
    assert "std::array<Client, MAX_CLIENTS>" in header
    init = (COMPONENT / "__init__.py").read_text()
    cap = re.search(r"MAX_CLIENTS = (\d+)", init)
    assert cap and f"MAX_CLIENTS = {cap.group(1)};" in header  # Python and C++ agree
    assert cpp.count("make_unique") == 1  # the ring, in setup(); later only sockets


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
    s3_part = doc[doc.index("## Wiring"):doc.index("## A classic ESP32 instead")]
    table = dict(re.findall(r"\| GPIO(\d+) \| `(\w+)` \|", s3_part))
    subs = yaml.load(CONFIG.read_text(), Loader=Loader)["substitutions"]
    assert {name: f"GPIO{n}" for n, name in table.items()} == {
        k: v for k, v in subs.items() if k.endswith("_pin")}
    host = cfg["esphome"]["name"]
    for server in cfg["serial_tcp"]:
        url = f"socket://{host}.local:{server['port']}"
        assert url in doc and url in CONFIG.read_text()


# --- ESPHome itself --------------------------------------------------------------


def esphome_command() -> str | None:
    """BUDDYBOT_ESPHOME, else the venv scripts/esphome.sh makes, else PATH."""
    if os.environ.get("BUDDYBOT_ESPHOME"):
        return os.environ["BUDDYBOT_ESPHOME"]
    version = re.search(r'^version=(\S+)$', INSTALLER.read_text(), re.M)
    assert version, "scripts/esphome.sh names the ESPHome version it installs"
    venv = cache_root() / f"esphome-{version.group(1)}"
    if (venv / ".complete").is_file():
        return str(venv / "bin" / "esphome")
    return shutil.which("esphome")


def offline_prefix() -> list[str]:
    """`unshare -n` where it works (root, or user namespaces): proof of no network."""
    unshare = shutil.which("unshare")
    if unshare is None:
        return []
    probe = subprocess.run([unshare, "-n", "true"], capture_output=True, check=False)
    return [unshare, "-n"] if probe.returncode == 0 else []


def copy_config(tmp_path: Path, edit: tuple[str, str] | None = None) -> Path:
    """The YAML, its components and the example secrets in a folder of their own."""
    text = CONFIG.read_text()
    if edit is not None:
        assert edit[0] in text, edit
        text = text.replace(edit[0], edit[1])
    (tmp_path / CONFIG.name).write_text(text)
    shutil.copytree(FOLDER / "components", tmp_path / "components")
    shutil.copy(SECRETS, tmp_path / "secrets.yaml")
    return tmp_path / CONFIG.name


def esphome(tmp_path: Path, *argv: str, subs: tuple[str, ...] = (),
            edit: tuple[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """`esphome [-s K V]... ARGV... radar-esp32.yaml` on a copy, offline."""
    command = esphome_command()
    if command is None:
        pytest.skip("ESPHome is not installed (not a test dependency: ~250 MB): "
                    "scripts/esphome.sh installs it in a venv of its own")
    assert shutil.which(command), f"BUDDYBOT_ESPHOME={command}: not an executable"
    config = copy_config(tmp_path, edit)
    line = [*offline_prefix(), command]
    for pair in subs:
        line += ["-s", *pair.split("=", 1)]
    return subprocess.run([*line, *argv, config.name], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120, check=False)


@pytest.mark.integration
def test_esphome_accepts_the_file_offline_without_a_warning(tmp_path: Path) -> None:
    done = esphome(tmp_path, "config")
    out = done.stdout + done.stderr
    assert done.returncode == 0 and "Configuration is valid!" in out, out
    assert "WARNING" not in out, out
    assert "port: 4001" in out and "baud_rate: 256000" in out and "serial_tcp" in out


@pytest.mark.integration
def test_esphome_accepts_the_classic_esp32_alternative(tmp_path: Path) -> None:
    doc = DOC.read_text()
    classic = doc[doc.index("## A classic ESP32 instead"):]
    subs = [f"{name}=GPIO{n}" for n, name in re.findall(r"\| GPIO(\d+) \| `(\w+)` \|", classic)]
    done = esphome(tmp_path, "config", subs=("board=esp32dev", *subs))
    out = done.stdout + done.stderr
    assert done.returncode == 0 and "WARNING" not in out, out


@pytest.mark.integration
@pytest.mark.parametrize(("sub", "said"), [
    ("radar0_tx_pin=GPIO27", "Failed config"),      # the SPI flash: refused
    ("radar0_rx_pin=GPIO45", "strapping PIN"),      # warned
    ("radar1_tx_pin=GPIO20", "USB-Serial-JTAG"),    # warned
])
def test_esphome_itself_catches_a_bad_pin(tmp_path: Path, sub: str, said: str) -> None:
    """The pin tables above can fail: ESPHome knows the ESP32-S3's pins too."""
    done = esphome(tmp_path, "config", subs=(sub,))
    assert said in done.stdout + done.stderr


@pytest.mark.integration
@pytest.mark.parametrize(("edit", "said"), [
    (("buffer_size: 1024            # a power", "buffer_size: 1000  # a power"),
     "buffer_size must be a power of two"),
    (("max_clients: 1               # the bridge", "max_clients: 5  # the bridge"),
     "max_clients"),
    (("    port: ${radar0_port}\n", ""), "'port' is a required option"),
])
def test_the_component_refuses_a_bad_setting(tmp_path: Path, edit: tuple[str, str],
                                             said: str) -> None:
    done = esphome(tmp_path, "config", edit=edit)
    out = done.stdout + done.stderr
    assert done.returncode != 0 and said in out, out


@pytest.mark.integration
def test_the_generated_firmware_source_compiles_for_syntax(tmp_path: Path) -> None:
    """`esphome compile --only-generate` writes main.cpp calling our setters;
    g++ then parses our component against the same ESPHome's headers and the
    build's own feature flags (the ESP-IDF itself is not here: the socket
    layer is taken from its host variant, the same BSD-socket API)."""
    done = esphome(tmp_path, "compile", "--only-generate")
    assert done.returncode == 0, done.stdout + done.stderr
    src = tmp_path / ".esphome" / "build" / "radar-esp32" / "src"
    main = (src / "main.cpp").read_text()
    for call in ("set_port(4001)", "set_port(4002)", "set_buffer_size(1024)",
                 "set_max_clients(1)", "set_uart_parent(radar0_uart)", "set_connected_sensor("):
        assert call in main, call
    gxx = shutil.which("g++")
    if gxx is None:
        pytest.skip("no g++ to parse the component's C++")
    defines = (src / "esphome" / "core" / "defines.h").read_text()
    assert "#define USE_SOCKET_IMPL_BSD_SOCKETS" in defines  # what the ESP32 build uses
    host = tmp_path / "host" / "esphome" / "core"
    host.mkdir(parents=True)
    kept = [line for line in defines.splitlines()
            if not re.match(r"#define USE_ESP(32|_IDF)", line)]
    (host / "defines.h").write_text("\n".join([*kept, "#define USE_HOST", ""]))
    python = Path(esphome_command() or "").parent / "python"
    if not python.exists():
        pytest.skip(f"no python beside {esphome_command()} to find ESPHome's headers")
    headers = Path(subprocess.run(
        [str(python), "-c",
         "import esphome, os; print(os.path.dirname(os.path.dirname(esphome.__file__)))"],
        capture_output=True, text=True, check=True, timeout=60).stdout.strip())
    parsed = subprocess.run(
        [gxx, "-std=gnu++20", "-fsyntax-only", "-Wall", "-Wextra", "-DESPHOME_LOG_LEVEL=6",
         f"-I{tmp_path / 'host'}", f"-I{headers}", str(COMPONENT / "serial_tcp.cpp")],
        capture_output=True, text=True, timeout=300, check=False)
    ours = [line for line in parsed.stderr.splitlines()
            if "serial_tcp" in line and ("error" in line or "warning" in line)]
    assert parsed.returncode == 0 and not ours, parsed.stderr
