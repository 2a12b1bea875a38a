"""Names on persons: the identity service's `NameSeen` joins the person holding
the followed face, sticks while they are present and their face is on the
track that was named, and is withdrawn at once when the face is of another
track or the track that gave it says it has no name (forgotten)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from buddybot.people.model import FaceSeen, Input, NameSeen, PeopleModel, Tick
from tests.properties import examples

from .test_model import SETTINGS, faces, ns, radar, radar_out, run, tick
from .test_model_radar import face_at, targets, walk


def name(t: float, track: int | None, who: str | None) -> NameSeen:
    return NameSeen(ns(t), track, who)


def names(model: PeopleModel) -> list[tuple[int, str | None]]:
    return [(p.id, p.name) for p in model.state()]


def test_the_name_of_the_followed_face_joins_its_person_and_makes_no_event() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 1.0)], model)
    assert names(model) == [(1, None)]
    assert run([name(1.0, 7, None)], model) == []  # the vote is not decided yet
    assert names(model) == [(1, None)]
    assert run([name(1.05, 7, "Ada")], model) == []
    assert names(model) == [(1, "Ada")]


def test_the_name_sticks_while_the_face_turns_away_and_goes_with_a_new_track() -> None:
    """Lost, the face is still theirs; back as a new track it may be someone else's
    (a wrong name is worse than none): withdrawn at once, until that track says."""
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 1.0), name(1.0, 7, "Ada"),
         name(1.6, None, None), tick(3.0)], model)  # no face followed
    assert names(model) == [(1, "Ada")]
    run([faces(3.1, 3.5), name(3.2, 8, None)], model)  # a new track, undecided
    assert names(model) == [(1, None)]
    run([name(3.5, 8, "Ada"), name(5.0, 7, None)], model)  # the old track says nothing now
    assert names(model) == [(1, "Ada")]


def tracked_faces(start: float, end: float, track: int) -> Iterator[FaceSeen]:
    """`faces`, each with the detector's track id."""
    for f in faces(start, end):
        yield dataclasses.replace(f, track=track)


def test_a_face_of_another_track_withdraws_the_name_before_the_identity_service_speaks(
        ) -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), tracked_faces(0.5, 1.0, 7), name(1.0, 7, "Ada"),
         tracked_faces(1.1, 1.5, 7)], model)
    assert names(model) == [(1, "Ada")]
    run([tracked_faces(1.6, 1.6, 8)], model)  # the detector follows someone else
    assert names(model) == [(1, None)]
    # The identity service's answer for the old track, late, is not given to the new one.
    run([name(1.65, 7, "Ada"), tracked_faces(1.7, 1.8, 8)], model)
    assert names(model) == [(1, None)]
    run([name(1.9, 8, "Grace"), tracked_faces(1.9, 2.0, 8)], model)
    assert names(model) == [(1, "Grace")]


def test_a_name_for_a_track_not_yet_seen_waits_for_its_face() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), tracked_faces(0.5, 1.0, 7), name(1.05, 8, "Grace")], model)
    assert names(model) == [(1, None)]  # the face is still track 7's
    run([tracked_faces(1.1, 1.1, 8)], model)
    assert names(model) == [(1, "Grace")]


def test_a_forgotten_name_is_cleared_at_once() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 2.0), name(1.0, 7, "Ada")], model)
    run([name(2.0, 7, None)], model)
    assert names(model) == [(1, None)]
    run([faces(2.1, 2.5)], model)  # the face alone does not bring it back
    assert names(model) == [(1, None)]


def test_another_name_for_the_face_replaces_it() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 1.0), name(1.0, 7, "Ada"), faces(1.1, 1.5),
         name(1.5, 9, "Grace")], model)
    assert names(model) == [(1, "Grace")]


def test_the_name_leaves_with_the_person_and_a_new_visit_starts_unnamed() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 1.0), name(1.0, 7, "Ada"), radar_out(1.2),
         name(1.2, None, None), tick(10.0)], model)
    assert names(model) == []
    run([radar(11.0), faces(11.5, 12.0)], model)
    assert names(model) == [(2, None)]


def test_a_name_before_any_face_waits_for_the_face() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), name(0.4, 7, "Ada")], model)
    assert names(model) == [(1, None)]  # radar only: no face to put it on
    run([faces(0.5, 0.6)], model)
    assert names(model) == [(1, "Ada")]


def test_an_old_name_is_ignored() -> None:
    model = PeopleModel(SETTINGS)
    run([radar(0.0), faces(0.5, 1.0), name(1.0, 7, "Ada"), name(0.9, 7, None)], model)
    assert names(model) == [(1, "Ada")]


def test_with_angle_radars_the_name_goes_to_the_person_holding_the_face() -> None:
    model = PeopleModel(SETTINGS)
    run([walk(0.0, 1.0, [(2.0, 0.8, 0.0, 0.0), (2.0, -1.0, 0.0, 0.0)]),
         face_at(1.05, 1.9, 0.78), name(1.06, 3, "Ada")], model)
    assert names(model) == [(1, None), (2, "Ada")]  # 2 is at y = 0.8, the face's
    # The face moves to the other person (a new face track, named Ada again by
    # mistake of nobody: the name is unique among those present).
    run([walk(1.1, 1.5, [(2.0, 0.8, 0.0, 0.0), (2.0, -1.0, 0.0, 0.0)]),
         face_at(1.55, 1.9, -0.98), name(1.56, 4, "Ada")], model)
    assert names(model) == [(1, "Ada"), (2, None)]


@pytest.mark.parametrize("who", ["", "   "])
def test_an_empty_name_is_refused(who: str) -> None:
    with pytest.raises(ValueError, match="empty"):
        NameSeen(0, 1, who)


NAMES = ("Ada", "Grace", "Alan")
steps = st.lists(st.tuples(st.sampled_from(["radar", "targets", "face", "name", "unnamed", "lost",
                                            "gap"]),
                           st.integers(1, 6)), max_size=40)


def timeline(plan: list[tuple[str, int]]) -> list[Input]:
    """Inputs in stamp order, 0.1 s apart (a gap: k * 0.7 s more)."""
    out: list[Input] = []
    t = 0.0
    for kind, k in plan:
        t += 0.1 + (0.7 * k if kind == "gap" else 0.0)
        if kind == "radar":
            out.append(radar(t, 1.0 + k / 4))
        elif kind == "targets":  # two people, left and right (angle radars)
            out.append(targets(t, (2.0, 0.9), (2.0, -0.9)))
        elif kind == "face":  # on the left or the right one, or straight ahead
            out.append(face_at(t, 1.9, (0.85, -0.85, 0.0)[k % 3]))
        elif kind == "name":
            out.append(name(t, k, NAMES[k % len(NAMES)]))
        elif kind == "unnamed":
            out.append(name(t, k, None))
        elif kind == "lost":
            out.append(name(t, None, None))
    return out


@settings(max_examples=examples(150))
@given(steps, st.integers(1, 8))
def test_ticks_change_no_name_and_a_name_is_on_one_person_at_most(
        plan: list[tuple[str, int]], every: int) -> None:
    inputs = timeline(plan)
    plain, ticked = PeopleModel(SETTINGS), PeopleModel(SETTINGS)
    last = 0
    for one in inputs:
        for at in range(last + ns(0.05) * every, one.stamp_ns, ns(0.05) * every):
            ticked.step(Tick(at))
        last = one.stamp_ns
        plain.step(one)
        ticked.step(one)
        assert names(plain) == names(ticked)
        present = [who for _, who in names(plain) if who is not None]
        assert len(present) == len(set(present))
