"""Simulated LD2410 sensors on real pseudo-terminals, stopped after each test."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import Script
from tests.radar.rig import Gated
from tests.radar.scripts import LD2410_SCRIPTS, LD2450_SCRIPTS, walk_in


@pytest.fixture
def sensor(tmp_path: Path) -> Iterator[PtySensor]:
    """One simulated LD2410 on a real pty, a person walking in."""
    with PtySensor(walk_in, link=tmp_path / "ttyLD2410") as sim:
        yield sim


@pytest.fixture
def sensors(tmp_path: Path) -> Iterator[Callable[..., PtySensor]]:
    """Makes simulated LD2410s on real ptys (scenario, link name, PtySensor options)."""
    made: list[PtySensor] = []

    def make(scenario: str | Script, name: str = "ttyLD", **kw: object) -> PtySensor:
        scripts = LD2450_SCRIPTS if kw.get("model") == "LD2450" else LD2410_SCRIPTS
        script = scripts[scenario] if isinstance(scenario, str) else scenario
        sensor = PtySensor(script, link=tmp_path / name, **kw).start()  # type: ignore[arg-type]
        if isinstance(scenario, Gated):
            scenario.sensor = sensor
        made.append(sensor)
        return sensor

    yield make
    for sensor in made:
        sensor.stop()
