"""The simulated camera films the simulated world: the real detector finds the people it
should see, where they are, and no one it should not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from buddybot.camera.world_view import WorldCamera
from buddybot.sim import faces, scenario, views
from buddybot.sim.world import PersonState, Snapshot, World
from tests.camera.networks import Networks

LENS = views.Lens(600.0, 600.0, 320.0, 240.0, 640, 480)
FACE_WIDTH_M = 0.15


def measured(networks: Networks, frame: np.ndarray) -> list[tuple[float, float]]:
    """(distance m, image x) of every face the detector finds, refined as the service does."""
    full, short = networks.face("full_sparse"), networks.face("short")
    out = []
    for found in full.detect(frame):
        det = short.refine(frame, found) or found
        x0, _, x1, _ = det.box
        out.append((LENS.fx * FACE_WIDTH_M / (x1 - x0), (x0 + x1) / 2))
    return out


@pytest.mark.parametrize("face", faces.names())
@pytest.mark.parametrize("distance", [0.8, 1.5, 2.5])
def test_every_photo_is_measured_at_its_true_distance(networks: Networks, face: str,
                                                      distance: float) -> None:
    person = PersonState(1, "", face, distance, 0.1, 0.15, 0.0, 0.0, math.pi)
    frame = WorldCamera(LENS).frame(Snapshot(0.0, 0, (person,), (), False))
    found = measured(networks, frame)
    assert len(found) == 1, found
    assert found[0][0] == pytest.approx(distance, rel=0.08)
    expected_u = LENS.cx - LENS.fx * person.y / person.x
    assert found[0][1] == pytest.approx(expected_u, abs=0.03 * LENS.width)


def test_the_visit_is_seen_while_it_faces_the_camera_and_not_once_it_turns_away(
        networks: Networks) -> None:
    w, cam = World(scenario.load("visit")), WorldCamera(LENS)
    for t in (3.0, 8.0, 16.0, 23.0):
        truth = w.at(t).people[0]
        found = measured(networks, cam.frame(w.at(t)))
        assert len(found) == 1 and found[0][0] == pytest.approx(truth.x, rel=0.08), (t, found)
    for t in (27.0, 35.0):  # walking away, then gone
        assert measured(networks, cam.frame(w.at(t))) == []


def test_the_detector_finds_exactly_the_faces_the_truth_says_are_visible(
        networks: Networks) -> None:
    cam = WorldCamera(LENS)
    for name, t in (("two_people", 20.0), ("crowd", 12.0), ("crowd", 20.0),
                    ("out_of_view", 5.0), ("dark", 10.0), ("passer_by", 4.5)):
        snap = World(scenario.load(name)).at(t)
        visible = [f for f in views.camera_view(snap, LENS) if f.visible]
        found = measured(networks, cam.frame(snap))
        assert len(found) == len(visible), (name, t, found, [f.person.id for f in visible])
        for face in visible:
            assert any(abs(u - face.u) < 20 and d == pytest.approx(face.depth_m, rel=0.1)
                       for d, u in found), (name, t, face, found)


def test_a_covered_camera_films_darkness() -> None:
    snap = World(scenario.load("dark")).at(10.0)
    assert float(WorldCamera(LENS).frame(snap).mean()) < 10
