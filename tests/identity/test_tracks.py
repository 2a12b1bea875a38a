"""The followed face's tracks: continued while the box overlaps, new on a jump or after
a loss, ids never reused."""

from __future__ import annotations

from buddybot.identity.tracks import FaceTracks, iou

S = 1_000_000_000


def test_iou_of_boxes() -> None:
    assert iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    assert iou((0, 0, 10, 10), (5, 0, 15, 10)) == 50 / 150
    assert iou((0, 0, 10, 10), (20, 20, 30, 30)) == 0.0
    assert iou((0, 0, 0, 0), (0, 0, 0, 0)) == 0.0


def test_a_moving_box_keeps_its_track_and_a_jump_starts_another() -> None:
    t = FaceTracks(min_iou=0.3, lost_s=1.0)
    assert t.update((100, 100, 200, 200), 0) == 1
    assert t.update((110, 105, 210, 205), S // 30) == 1
    assert t.update((400, 100, 500, 200), 2 * S // 30) == 2
    assert t.update((100, 100, 200, 200), 3 * S // 30) == 3  # back: still a new track


def test_a_short_gap_keeps_the_track_and_a_long_one_ends_it() -> None:
    t = FaceTracks(min_iou=0.3, lost_s=1.0)
    t.update((0, 0, 50, 50), 0)
    assert t.update(None, S // 2) == 1
    assert t.update((0, 0, 50, 50), S // 2 + 1) == 1
    assert t.update(None, 2 * S) is None
    assert t.update((0, 0, 50, 50), 2 * S + 1) == 2  # same place, later: a new track


def test_ids_are_never_reused() -> None:
    t = FaceTracks(min_iou=0.9, lost_s=0.1)
    seen = [t.update((float(i * 100), 0, float(i * 100 + 50), 50), i * S) for i in range(50)]
    assert seen == list(range(1, 51))


def test_the_detectors_track_id_is_the_track_when_it_gives_one() -> None:
    """The detector knows whom it follows: its id wins over the boxes' overlap, so a
    name is decided for the track the people service sees on the face."""
    t = FaceTracks(min_iou=0.3, lost_s=1.0)
    assert t.update((100, 100, 200, 200), 0, given=700) == 700
    assert t.update((400, 100, 500, 200), S // 30, given=700) == 700  # moved fast, same one
    assert t.update((400, 100, 500, 200), 2 * S // 30, given=701) == 701  # another person
    assert t.update(None, 3 * S // 30) == 701  # a missed frame keeps it ...
    assert t.update(None, 2 * S) is None  # ... `lost_s` ends it
    assert t.update((0, 0, 50, 50), 2 * S + 1) == 1  # a source without ids: tracks of its own
