"""docs/hardware.md and its wiring diagram agree, and the diagram is sound.

The diagram is hand-written SVG; a builder follows it with the page's wiring
table beside it, so every pin the table names must be drawn (and labelled)
in the SVG. The PNG the page shows is a screenshot of the SVG: it must have
the SVG's size, or it was not made from this drawing. Every relative link of
the page must lead to a file, since the page is where a builder starts.
"""

from __future__ import annotations

import re
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "hardware.md"
SVG = ROOT / "docs" / "images" / "wiring.svg"
PNG = ROOT / "docs" / "images" / "wiring.png"
NS = "{http://www.w3.org/2000/svg}"


def svg_texts() -> list[list[str]]:
    """Each <text> element of the diagram as its tokens (split on spaces,
    commas and brackets), so "GPIO4 (RX)" holds the pin "GPIO4" but "RXD"
    does not hold "RX"."""
    root = ET.parse(SVG).getroot()  # raises on a file that is not XML
    assert root.tag == f"{NS}svg"
    texts = ["".join(el.itertext()) for el in root.iter(f"{NS}text")]
    return [t for t in (re.split(r"[\s,()]+", s.strip()) for s in texts) if t]


def wiring_pins() -> set[str]:
    """The pin columns (2nd and 4th) of the table under "## Wiring"."""
    text = DOC.read_text()
    section = text[text.index("## Wiring"):]
    section = section[:section.index("\n## ", 1)] if "\n## " in section[1:] else section
    rows = [line for line in section.splitlines() if line.startswith("| ")]
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    assert header == ["from", "pin", "to", "pin", "wire"], header
    pins: set[str] = set()
    for row in rows[1:]:  # past the header (the |---| line is not "| ...")
        cells = [c.strip() for c in row.strip("|").split("|")]
        for cell in (cells[1], cells[3]):
            pins.update(p.strip() for p in cell.split(",") if p.strip())
    return pins - {"+ and −"}  # the speaker's terminals, drawn as its symbol


def drawn(pin: str, texts: list[list[str]]) -> bool:
    want = pin.split()
    return any(tokens[i:i + len(want)] == want
               for tokens in texts for i in range(len(tokens) - len(want) + 1))


def test_the_diagram_is_svg_with_a_size() -> None:
    root = ET.parse(SVG).getroot()
    assert root.tag == f"{NS}svg"
    assert root.get("viewBox") and int(root.get("width", "0")) >= 1000
    assert root.find(f"{NS}title") is not None  # read by screen readers


def test_every_pin_of_the_wiring_table_is_in_the_diagram() -> None:
    texts = svg_texts()
    pins = wiring_pins()
    assert {"VCC", "GND", "TX", "RX", "RXD", "TXD", "5V", "GPIO4", "GPIO7",
            "HDMI 1", "L+"} <= pins, pins
    missing = sorted(p for p in pins if not drawn(p, texts))
    assert not missing, f"pins in docs/hardware.md's wiring table but not in the diagram: {missing}"


def test_a_pin_missing_from_the_diagram_is_found() -> None:
    """The check above can fail: a pin the drawing lacks is not `drawn`."""
    texts = svg_texts()
    assert drawn("GPIO6", texts) and not drawn("GPIO16", texts)
    assert drawn("RXD", texts) and not drawn("RXD2", texts)
    assert drawn("HDMI 2", texts) and not drawn("HDMI 3", texts)


def test_the_diagrams_pins_are_the_esp32_files() -> None:
    """Route B's GPIOs are the ones the ESPHome file configures."""
    yaml_text = (ROOT / "deploy" / "esphome" / "radar-esp32.yaml").read_text()
    configured = set(re.findall(r"radar[01]_(?:rx|tx)_pin: (GPIO\d+)", yaml_text))
    drawn_gpios = {t for tokens in svg_texts() for t in tokens if re.fullmatch(r"GPIO\d+", t)}
    assert configured and drawn_gpios == configured


def test_the_png_is_a_render_of_the_svg() -> None:
    data = PNG.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])  # the IHDR chunk
    root = ET.parse(SVG).getroot()
    assert (width, height) == (int(root.get("width", "0")), int(root.get("height", "0")))
    assert "images/wiring.png" in DOC.read_text() and "images/wiring.svg" in DOC.read_text()


def test_every_relative_link_of_the_page_leads_to_a_file() -> None:
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", DOC.read_text())
    local = [link for link in links if "://" not in link]
    assert len(local) >= 10
    missing = [link for link in local if not (DOC.parent / link).exists()]
    assert not missing, missing


def test_the_page_says_what_was_not_tried() -> None:
    text = DOC.read_text()
    assert "What was tried on real hardware: nothing." in text
    assert "pseudo-terminals" in text and "simulated" in text
