"""A simulated LD2450's brain: configuration state, command ACKs, report frames.

No I/O and driven by explicit time, like `SimulatedLD2410`; `sim.PtySensor`
puts either behind a pseudo-terminal (`model="LD2450"`). It applies its own
settings as the module does: single-target mode reports only the first
person, a zone filter drops people outside (mode 1) or inside (mode 2) its
rectangles, a restart makes it silent for a moment and Bluetooth off
makes the MAC query answer the placeholder MAC.
"""

from __future__ import annotations

import struct
from dataclasses import KW_ONLY, dataclass, field

from buddybot.radar import envelope as e
from buddybot.radar import ld2450 as p
from buddybot.radar.sim_commands import AnswersCommands
from buddybot.radar.sim_scene import AngleScript, Person

FIRMWARE = (0x0000, 0x0202, 0x23090617)  # type, major (2.02), minor: V2.02.23090617
RESOLUTION_MM = 320


def _inside(zone: p.Zone, person: Person) -> bool:
    x_lo, x_hi = sorted((zone.x1, zone.x2))
    y_lo, y_hi = sorted((zone.y1, zone.y2))
    return x_lo <= person.x_mm <= x_hi and y_lo <= person.y_mm <= y_hi


@dataclass
class SimulatedLD2450(AnswersCommands):
    """Protocol state of one LD2450."""

    scenario: AngleScript
    _: KW_ONLY
    firmware: tuple[int, int, int] = FIRMWARE
    tracking_mode: int = 2  # 1 single, 2 multi (factory)
    zone_filter: p.ZoneFilter = field(default_factory=lambda: p.ZoneFilter(p.ZONE_OFF))
    mac: bytes = bytes.fromhex("c4f2a1b05e77")

    # -- reports --

    def visible(self, people: tuple[Person, ...]) -> list[Person]:
        """Who the module reports, after its zone filter and tracking mode."""
        zf = self.zone_filter
        used = [z for z in zf.zones if z != p.EMPTY_ZONE]
        if zf.mode == p.ZONE_DETECT_ONLY:
            people = tuple(x for x in people if any(_inside(z, x) for z in used))
        elif zf.mode == p.ZONE_IGNORE:
            people = tuple(x for x in people if not any(_inside(z, x) for z in used))
        return list(people[:1 if self.tracking_mode == 1 else p.SLOTS])

    def report(self, t: float, now: float) -> bytes:
        """The bytes the sensor sends at scenario time `t` (nothing while configuring
        or rebooting)."""
        if self.silent(now):
            return b""
        scene = self.scenario(t, self.rng)
        slots: list[p.Target | None] = [
            p.Target(x.x_mm, x.y_mm, x.speed_cms, RESOLUTION_MM)
            for x in self.visible(scene.people)]
        slots += [None] * (p.SLOTS - len(slots))
        frame = p.encode_report(p.Report(tuple(slots)))
        if scene.corrupt:
            frame = frame[:-1] + b"\x00"
        if scene.truncate:
            frame = frame[:p.REPORT_SIZE // 2]
        return scene.garbage + frame

    # -- commands --

    def _apply(self, word: int, value: bytes, now: float) -> bytes:
        """Execute a configuration command; ValueError -> failure ACK."""
        if word == p.CMD_SINGLE_TARGET:
            self.tracking_mode = 1
        elif word == p.CMD_MULTI_TARGET:
            self.tracking_mode = 2
        elif word == p.CMD_QUERY_TRACKING_MODE:
            return struct.pack("<H", self.tracking_mode)
        elif word == p.CMD_SET_ZONE_FILTER:
            if len(value) != 26:
                raise ValueError("bad zone value")
            self.zone_filter = p.decode_zone_filter(value)
        elif word == p.CMD_QUERY_ZONE_FILTER:
            return p.encode_zone_filter(self.zone_filter)
        elif word == e.CMD_READ_MAC:
            return self.mac if self.bluetooth else bytes.fromhex("080504030201")
        else:
            raise ValueError(f"unknown command 0x{word:04X}")
        return b""

    def _factory_defaults(self) -> None:
        self.tracking_mode = 2
        self.zone_filter = p.ZoneFilter(p.ZONE_OFF)
