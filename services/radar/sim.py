"""A simulated LD2410 or LD2450 speaking the real byte protocol through a pseudo-terminal.

`SimulatedLD2410` (here) and `SimulatedLD2450` (ld2450_sim.py) are the
sensors' brains (configuration state, command ACKs, report frames from a
scenario); `PtySensor` puts one behind a pty (`model="LD2410"` or
`"LD2450"`) so the bridge and the tools exercise exactly the serial path
they use with hardware. `unplug()`/`replug()` re-create the pty behind the
same path (a symlink), which is what a USB sensor does when it is pulled
and put back.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import struct
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field, replace
from pathlib import Path

from buddybot.radar import ld2410 as p
from buddybot.radar import ld2450
from buddybot.radar.ld2450_sim import SimulatedLD2450
from buddybot.radar.sim_commands import AnswersCommands
from buddybot.radar.sim_scene import AngleScript, Script, Target

log = logging.getLogger("buddybot.radar.sim")

FRAME_PERIOD_S = 0.1  # the module reports about 10 times per second
MODELS = ("LD2410", "LD2450")
DEFAULT_MOVING_SENSITIVITY = (50, 50, 40, 30, 20, 15, 15, 15, 15)
DEFAULT_STILL_SENSITIVITY = (0, 0, 40, 40, 30, 30, 20, 20, 20)
FIRMWARE = (0x0100, 0x0107, 0x22091615)  # type, major (1.07), minor
FIRMWARE_V2 = (0x0100, 0x0204, 0x23022511)  # an LD2410C with light level and OUT pin bytes
NOISE_RESULT_S = 1.0  # how long reports say "noise detection succeeded/failed" afterwards


def default_parameters() -> p.Parameters:
    return p.Parameters(8, 8, 8, DEFAULT_MOVING_SENSITIVITY, DEFAULT_STILL_SENSITIVITY, 5)


@dataclass
class SimulatedLD2410(AnswersCommands):
    """Protocol state of one sensor: no I/O, driven by explicit time."""

    scenario: Script
    _: KW_ONLY
    firmware: tuple[int, int, int] = FIRMWARE
    engineering: bool = True
    params: p.Parameters = field(default_factory=default_parameters)
    resolution_index: int = 0
    light: bytes = b"\x00\x80\x00\x00"
    mac: bytes = bytes.fromhex("8f27c6d91a3b")
    # The two bytes after the gate energies; None: a light level and the OUT pin.
    aux_bytes: tuple[int, int] | None = None
    bluetooth_password: str = "HiLink"
    bluetooth_authorised: bool = False
    noise_detection_fails: bool = False
    _noise_start: float | None = None
    _noise_end: float = 0.0

    # -- reports --

    def report(self, t: float, now: float) -> bytes:
        """The bytes the sensor sends at scenario time `t` (nothing while configuring
        or rebooting)."""
        if self.silent(now):
            return b""
        target = self._noise_target(now) or self.scenario(t, self.rng)
        frame = p.encode_report(self._report(target))
        if target.corrupt:
            frame = frame[:-1] + b"\x00"
        return target.garbage + frame

    def noise_status(self, now: float) -> int:
        """0x001B's answer: 0 never started, 1 in progress, 2 completed."""
        if self._noise_start is None:
            return 0
        return 1 if now < self._noise_end else 2

    def _noise_target(self, now: float) -> Target | None:
        """While measuring background noise (and shortly after) the module sends
        target states 4..6 instead of targets (LD2410C auto thresholds)."""
        if self._noise_start is None or now >= self._noise_end + NOISE_RESULT_S:
            return None
        if now < self._noise_end:
            return Target(p.STATE_NOISE_DETECTING)
        return Target(p.STATE_NOISE_DETECTION_FAILED if self.noise_detection_fails
                      else p.STATE_NOISE_DETECTION_SUCCEEDED)

    def _report(self, target: Target) -> p.Report:
        if not self.engineering:
            return p.Report(target.state, target.moving_cm, target.moving_energy, target.still_cm,
                            target.still_energy, target.detection_cm)
        gate_cm = 75 if self.resolution_index == 0 else 20
        moving = [self.rng.randint(0, 8) for _ in range(9)]
        still = [self.rng.randint(0, 8) for _ in range(9)]
        if target.state in (1, 3):
            moving[min(8, target.moving_cm // gate_cm)] = min(100, target.moving_energy)
        if target.state in (2, 3):
            still[min(8, target.still_cm // gate_cm)] = min(100, target.still_energy)
        light, out = self.aux_bytes or (self.rng.randint(60, 80), int(target.state in (1, 2, 3)))
        return p.Report(
            target.state, target.moving_cm, target.moving_energy, target.still_cm,
            target.still_energy, target.detection_cm, engineering=True,
            max_moving_gate=8, max_still_gate=8, moving_gate_energy=tuple(moving),
            still_gate_energy=tuple(still), light_level=light, out_pin=out,
        )

    # -- commands --

    def _apply(self, word: int, value: bytes, now: float) -> bytes:
        """Execute a configuration command; ValueError -> failure ACK."""
        if word == p.CMD_SET_MAX_GATES:
            words = _words(value, (0, 1, 2))
            moving, still, duration = words[0], words[1], words[2]
            if not (2 <= moving <= 8 and 2 <= still <= 8 and duration <= 0xFFFF):
                raise ValueError("out of range")
            self.params = replace(self.params, max_moving_gate=moving, max_still_gate=still,
                                  no_one_duration_s=duration)
        elif word == p.CMD_READ_PARAMETERS:
            return p.encode_parameters(self.params)
        elif word in (p.CMD_ENGINEERING_ON, p.CMD_ENGINEERING_OFF):
            self.engineering = word == p.CMD_ENGINEERING_ON
        elif word == p.CMD_SET_SENSITIVITY:
            words = _words(value, (0, 1, 2))
            gate, moving, still = words[0], words[1], words[2]
            if moving > 100 or still > 100 or (gate > 8 and gate != 0xFFFF):
                raise ValueError("out of range")
            ms, ss = list(self.params.moving_sensitivity), list(self.params.still_sensitivity)
            for g in range(9) if gate == 0xFFFF else (gate,):
                ms[g], ss[g] = moving, still
            self.params = replace(self.params, moving_sensitivity=tuple(ms),
                                  still_sensitivity=tuple(ss))
        elif word == p.CMD_READ_MAC:
            return self.mac
        elif word == p.CMD_AUTO_THRESHOLDS:
            (duration,) = struct.unpack("<H", value)
            if duration == 0:
                raise ValueError("bad duration")
            self._noise_start, self._noise_end = now, now + duration
        elif word == p.CMD_AUTO_THRESHOLDS_STATUS:
            return struct.pack("<H", self.noise_status(now))
        elif word == p.CMD_BLUETOOTH_AUTH:
            self.bluetooth_authorised = value == self.bluetooth_password.encode("ascii")
            if not self.bluetooth_authorised:
                raise ValueError("wrong password")
        elif word == p.CMD_BLUETOOTH_PASSWORD:
            text = value.decode("ascii", "replace")
            if len(value) != p.BLUETOOTH_PASSWORD_LENGTH or not text.isprintable():
                raise ValueError("bad password")
            self.bluetooth_password = text
        elif word == p.CMD_SET_RESOLUTION:
            (index,) = struct.unpack("<H", value)
            if index not in p.RESOLUTIONS:
                raise ValueError("bad resolution")
            self.resolution_index = index
        elif word == p.CMD_READ_RESOLUTION:
            return struct.pack("<H", self.resolution_index)
        elif word == p.CMD_SET_LIGHT_CONTROL:
            if len(value) != 4:
                raise ValueError("bad light control")
            self.light = value
        elif word == p.CMD_READ_LIGHT_CONTROL:
            return self.light
        else:
            raise ValueError(f"unknown command 0x{word:04X}")
        return b""

    def _factory_defaults(self) -> None:
        self.params = default_parameters()
        self.resolution_index = 0

    def _restarted(self) -> None:
        self.engineering = False  # not kept across a restart


def _words(value: bytes, expected: tuple[int, ...]) -> list[int]:
    """Decode `word(2) dword(4)` pairs with the expected parameter words."""
    if len(value) != 6 * len(expected):
        raise ValueError("bad value length")
    out = []
    for i, want in enumerate(expected):
        word, number = struct.unpack_from("<HI", value, 6 * i)
        if word != want:
            raise ValueError("bad parameter word")
        out.append(number)
    return out


class PtySensor:
    """A simulated sensor on a pty; `path` (a symlink if `link` is given) is its port.

    `model` chooses the brain: "LD2410" (`script` gives a `Target`;
    `engineering`, `firmware`, `aux_bytes` apply) or "LD2450" (`script` gives
    a `Scene`). The script is asked at the scenario time `clock()` gives:
    by default the seconds since the sensor was made, times `speed`; the
    simulated world passes its shared clock (`world_view.world_sensor`).
    """

    def __init__(self, script: Script | AngleScript, *,
                 link: Path | None = None, speed: float = 1.0, engineering: bool = True,
                 seed: int = 1, answer_commands: bool = True,
                 firmware: tuple[int, int, int] | None = None,
                 aux_bytes: tuple[int, int] | None = None, model: str = "LD2410",
                 clock: Callable[[], float] | None = None) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown model {model!r}; one of {MODELS}")
        self.model = model
        self.sim: SimulatedLD2410 | SimulatedLD2450
        self._parser: p.Parser | ld2450.Parser
        if model == "LD2450":
            self.sim = SimulatedLD2450(script, seed=seed,  # type: ignore[arg-type]
                                       answer_commands=answer_commands)
            if firmware is not None:
                self.sim.firmware = firmware
            self._parser = ld2450.Parser()
        else:
            self.sim = SimulatedLD2410(script, engineering=engineering,  # type: ignore[arg-type]
                                       seed=seed, answer_commands=answer_commands,
                                       firmware=firmware or FIRMWARE, aux_bytes=aux_bytes)
            self._parser = p.Parser()
        self.speed = speed
        self._clock = clock
        self.link = link
        self.frames_sent = 0
        self.frames_dropped = 0
        self._lock = threading.Lock()
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = time.monotonic()
        self._open()

    @property
    def path(self) -> str:
        """The port to open: the symlink if any, else the pty's slave device."""
        return str(self.link) if self.link else self._slave_name

    def scenario_time(self) -> float:
        if self._clock is not None:
            return self._clock()
        return (time.monotonic() - self._t0) * self.speed

    # -- lifetime --

    def start(self) -> PtySensor:
        self._thread = threading.Thread(target=self._run, name=f"{self.model}-sim",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        self._close()
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()

    def __enter__(self) -> PtySensor:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def unplug(self) -> None:
        """The sensor disappears: the pty is closed and the symlink removed."""
        self._close()
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()

    def replug(self) -> None:
        """The sensor comes back: a new pty behind the same path."""
        self._open()

    def plugged(self) -> bool:
        return self._master is not None

    def _open(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: bytes are bytes
        os.set_blocking(master, False)
        name = os.ttyname(slave)
        with self._lock:
            self._master, self._slave, self._slave_name = master, slave, name
            self._parser.reset()
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".tmp")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            tmp.symlink_to(name)
            os.replace(tmp, self.link)

    def _close(self) -> None:
        with self._lock:
            fds = (self._master, self._slave)
            self._master = self._slave = None
        for fd in fds:
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)

    # -- the sensor's loop --

    def _write(self, data: bytes) -> bool:
        with self._lock:
            if self._master is None:
                return False
            try:
                os.write(self._master, data)
                return True
            except (BlockingIOError, OSError):
                return False

    def _run(self) -> None:
        next_frame = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            wait = max(0.0, next_frame - now)
            master = self._master
            if master is None:
                self._stop.wait(min(wait, 0.05) or 0.01)
            else:
                try:
                    ready, _, _ = select.select([master], [], [], wait)
                    if ready:
                        self._handle(os.read(master, 4096))
                except (OSError, ValueError):
                    self._stop.wait(0.01)  # closed under us by unplug()
            now = time.monotonic()
            if now >= next_frame:
                next_frame += FRAME_PERIOD_S
                if now - next_frame > 1.0:  # fell far behind (suspended): catch up
                    next_frame = now + FRAME_PERIOD_S
                data = self.sim.report(self.scenario_time(), now)
                if data and self._master is not None:
                    if self._write(data):
                        self.frames_sent += 1
                    else:
                        self.frames_dropped += 1

    def _handle(self, data: bytes) -> None:
        for frame in self._parser.feed(data):
            if isinstance(frame, p.Command):
                ack = self.sim.handle(frame, time.monotonic())
                if ack:
                    self._write(ack)
