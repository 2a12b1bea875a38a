"""What a simulated radar sees at a moment: the input of the simulators (pure types).

The simulated world (`world_view.py`) and the scripted line faults of the
tests both produce these; `SimulatedLD2410` turns a `Target` into report
frames, `SimulatedLD2450` a `Scene`. A script is a function of the
scenario time and a random source (for line noise).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass

NO_TARGET, MOVING, STILL, BOTH = 0, 1, 2, 3


@dataclass(frozen=True)
class Target:
    """What an LD2410 reports (distances cm, energies 0..100+)."""

    state: int = NO_TARGET
    moving_cm: int = 0
    moving_energy: int = 0
    still_cm: int = 0
    still_energy: int = 0
    detection_cm: int = 0
    garbage: bytes = b""  # bytes the noisy line adds before this frame
    corrupt: bool = False  # send this frame with a broken tail


NOBODY = Target()


@dataclass(frozen=True)
class Person:
    """One LD2450 target in the sensor's axes: mm, mm, cm/s (+ = moving away)."""

    x_mm: int
    y_mm: int
    speed_cms: int = 0


@dataclass(frozen=True)
class Scene:
    """What an LD2450 reports now; `garbage`/`corrupt`/`truncate` model a noisy line."""

    people: tuple[Person, ...] = ()
    garbage: bytes = b""  # bytes the line adds before this frame
    corrupt: bool = False  # send this frame with a broken end
    truncate: bool = False  # send only the first half of this frame


EMPTY = Scene()

Script = Callable[[float, random.Random], Target]
"""Scenario time (s), random source -> what an LD2410 reports."""
AngleScript = Callable[[float, random.Random], Scene]
"""Scenario time (s), random source -> what an LD2450 reports."""
