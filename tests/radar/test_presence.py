"""The presence rule (pure): base rule, hysteresis, holds, stale sensors; angle-radar
(LD2450) reports through the zones, and both models at once."""

from __future__ import annotations

import random

import msgspec
import pytest

from buddybot.contract.messages import PresenceState, PresenceTarget, RadarTarget
from buddybot.radar.presence import (
    PresenceTracker,
    Reading,
    SensorReading,
    TargetsReading,
    Verdict,
    read_targets,
)
from buddybot.radar.settings import RadarPresenceSettings, RadarZone
from tests.radar.rig import radar_target
from tests.radar.scripts import LD2410_SCRIPTS as SCENARIOS

IN, OUT = PresenceState.IN_RANGE, PresenceState.OUT_OF_RANGE
MOVING, STANDING = PresenceTarget.MOVING, PresenceTarget.STANDING


def at(cm: int, state: int = 1) -> Reading:
    return Reading(state, cm, cm, cm)


NOBODY = Reading(0, 0)


class Clock:
    """Feeds readings at 10 Hz and collects verdicts."""

    def __init__(self, rules: RadarPresenceSettings | None = None) -> None:
        self.tracker = PresenceTracker(rules or RadarPresenceSettings())
        self.t = 0.0
        self.verdicts: list[Verdict] = []

    def feed(self, reading: SensorReading, seconds: float = 0.1, sensor: str = "0/0") -> None:
        steps = max(1, round(seconds / 0.1))
        for _ in range(steps):
            v = self.tracker.update(sensor, reading, self.t, round(self.t * 1e9))
            if v:
                self.verdicts.append(v)
            self.t += 0.1

    def idle(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.05)):
            v = self.tracker.tick(self.t)
            if v:
                self.verdicts.append(v)
            self.t += 0.05

    @property
    def states(self) -> list[tuple[PresenceState, PresenceTarget]]:
        return [(v.presence, v.target) for v in self.verdicts]


def test_seed_rule_nearest_valid_sensor_wins() -> None:
    tracker = PresenceTracker(RadarPresenceSettings(range_m=2.0))
    assert tracker.update("0/0", at(300), 0.0, 1) is None
    # Sensor 1 has no target at a smaller distance: ignored (NO_TARGET).
    assert tracker.update("0/1", Reading(0, 50), 0.0, 2) is None
    v = tracker.update("0/2", at(150, 2), 0.0, 3)
    assert v == Verdict(IN, STANDING, 1.5, 3)


def test_entering_needs_no_hold_and_is_stamped_with_the_frame() -> None:
    c = Clock()
    c.feed(at(350), 1.0)
    c.feed(at(199))
    assert c.states == [(IN, MOVING)]
    assert c.verdicts[0].stamp_ns == 1_000_000_000
    assert c.verdicts[0].distance_m == 1.99


def test_exactly_on_the_range_is_in_range() -> None:
    c = Clock()
    c.feed(at(200))
    assert c.states == [(IN, MOVING)]


@pytest.mark.parametrize(("state", "target"), [(1, MOVING), (2, STANDING), (3, MOVING)])
def test_standing_only_for_stationary_only(state: int, target: PresenceTarget) -> None:
    c = Clock()
    c.feed(at(100, state))
    assert c.states == [(IN, target)]


def test_hysteresis_jitter_around_the_border_does_not_flap() -> None:
    c = Clock(RadarPresenceSettings(range_m=2.0, exit_margin_m=0.3, absence_hold_s=0.0))
    for cm in [195, 205, 215, 190, 225, 229, 210, 199] * 5:
        c.feed(at(cm))
    assert c.states == [(IN, MOVING)]
    c.feed(at(231))
    assert c.states == [(IN, MOVING), (OUT, MOVING)]
    c.feed(at(210))  # re-entering needs the range itself
    assert len(c.verdicts) == 2
    c.feed(at(200))
    assert c.states[-1] == (IN, MOVING)


def test_absence_hold_bridges_no_target_blips() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=3.0))
    c.feed(at(100))
    for _ in range(10):
        c.feed(NOBODY, 1.0)
        c.feed(at(100), 0.2)
    assert c.states == [(IN, MOVING)]
    absent_from = c.t
    c.feed(NOBODY, 2.9)
    assert len(c.verdicts) == 1
    c.feed(NOBODY, 0.3)
    assert c.states == [(IN, MOVING), (OUT, MOVING)]
    assert c.verdicts[-1].distance_m == 0.0
    # Published after the hold, stamped with the first frame of the absence: a
    # consumer holding absence too counts from the same moment, not after this hold.
    assert c.verdicts[-1].stamp_ns == round(absent_from * 1e9)


def test_absence_hold_expires_on_ticks_without_frames_from_the_person() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=1.0, stale_after_s=5.0))
    c.feed(at(100))
    c.feed(at(400), 0.1)  # walked out of range, sensor then quiet
    c.idle(1.2)
    assert c.states == [(IN, MOVING), (OUT, MOVING)]
    assert c.verdicts[-1].distance_m == 4.0


def test_target_kind_change_needs_to_last() -> None:
    c = Clock(RadarPresenceSettings(target_hold_s=1.0))
    c.feed(at(100, 2))
    for _ in range(20):  # fidgeting: STATIONARY/BOTH flicker
        c.feed(at(100, 3), 0.3)
        c.feed(at(100, 2), 0.3)
    assert c.states == [(IN, STANDING)]
    c.feed(at(100, 1), 1.2)
    assert c.states == [(IN, STANDING), (IN, MOVING)]


def test_stale_sensor_is_excluded_not_taken_for_nobody() -> None:
    rules = RadarPresenceSettings(absence_hold_s=1.0, stale_after_s=1.5)
    c = Clock(rules)
    c.feed(at(100), sensor="0/0")
    assert c.states == [(IN, MOVING)]
    # Sensor 0/0 falls silent; there is no other sensor: the verdict is kept.
    c.idle(10.0)
    assert c.tracker.stale_sensors(c.t) == ["0/0"]
    assert c.states == [(IN, MOVING)]
    # Another sensor appears and sees nobody: the silent one's "person" is not
    # counted, so after the hold the robot believes the fresh sensor.
    c.feed(NOBODY, 1.2, sensor="0/1")
    assert c.states == [(IN, MOVING), (OUT, MOVING)]


def test_ids_silent_before_they_were_established_are_forgotten_not_silent() -> None:
    """What a flood leaves in the table: ids heard once. They are not sensors
    that fell silent (that read "15 of 16 sensor(s) silent" for ever)."""
    c = Clock(RadarPresenceSettings(stale_after_s=1.5))
    c.feed(NOBODY, 1.2, sensor="0/0")
    for i in range(40):
        c.feed(NOBODY, sensor=f"evil/{i}")
    c.feed(NOBODY, 0.5, sensor="0/0")
    assert len(c.tracker.known_sensors()) == 16
    for _ in range(30):  # the real one keeps talking, the invented ones are gone
        c.feed(NOBODY, sensor="0/0")
        c.tracker.tick(c.t)
    assert c.tracker.known_sensors() == ["0/0"] and c.tracker.stale_sensors(c.t) == []
    assert c.tracker.evicted == 40
    c.idle(2.0)  # an established sensor falling silent is still reported
    assert c.tracker.stale_sensors(c.t) == ["0/0"]


def test_stale_sensors_last_person_does_not_keep_presence() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.5, stale_after_s=1.0))
    c.feed(at(100), sensor="0/0")
    c.feed(NOBODY, sensor="0/1")
    for _ in range(30):  # only 0/1 keeps talking
        c.feed(NOBODY, sensor="0/1")
    assert c.states == [(IN, MOVING), (OUT, MOVING)]


def test_sensor_coming_back_is_used_again() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.5, stale_after_s=1.0))
    c.feed(NOBODY, 0.5, sensor="0/0")
    c.idle(2.0)
    assert c.tracker.stale_sensors(c.t) == ["0/0"]
    c.feed(at(100), sensor="0/0")
    assert c.tracker.stale_sensors(c.t) == []
    assert c.states == [(OUT, MOVING), (IN, MOVING)]


def test_unknown_start_says_out_of_range_after_the_hold() -> None:
    """A restarted service must contradict a stale latched IN_RANGE of its previous life."""
    c = Clock(RadarPresenceSettings(absence_hold_s=2.0))
    c.feed(NOBODY, 1.9)
    assert c.verdicts == []
    c.feed(NOBODY, 0.2)
    assert c.states == [(OUT, MOVING)]
    c.feed(NOBODY, 5.0)
    assert len(c.verdicts) == 1


def test_no_data_at_all_says_nothing() -> None:
    c = Clock()
    c.idle(10.0)
    assert c.verdicts == [] and c.tracker.presence is None


def test_zero_detection_distance_falls_back_to_the_reported_kind() -> None:
    assert Reading(2, 0, 50, 180).distance_m == 1.8
    assert Reading(1, 0, 50, 180).distance_m == 0.5


@pytest.mark.parametrize("bad", [
    {"range_m": 0}, {"exit_margin_m": -1}, {"absence_hold_s": -0.1}, {"stale_after_s": 0},
    {"max_sensors": 0}, {"max_sensors": 100_000},
])
def test_rules_refuse_nonsense(bad: dict[str, float]) -> None:
    """The rules are the `[radar_presence]` struct: its ranges refuse these at decode."""
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(bad, RadarPresenceSettings)


@pytest.mark.parametrize("state", [4, 5, 6])
def test_noise_detection_states_mean_no_target_not_silence(state: int) -> None:
    """LD2410C background-noise detection (states 4-6): fresh frames without a
    target, so the person leaves after the hold (a silent sensor would keep IN)."""
    c = Clock(RadarPresenceSettings(absence_hold_s=1.0))
    c.feed(at(100))
    c.feed(Reading(state, 0), 1.5)
    assert c.states == [(IN, MOVING), (OUT, MOVING)]
    assert c.tracker.stale_sensors(c.t) == []
    fresh = Clock(RadarPresenceSettings(absence_hold_s=1.0))
    fresh.feed(Reading(state, 50, 50, 50), 1.5)  # distances in such frames mean nothing
    assert fresh.states == [(OUT, MOVING)]


def test_a_flood_of_invented_sensor_ids_is_bounded_and_changes_nothing() -> None:
    """28k fake sensors saying "nobody" between the real sensor's frames (10 Hz):
    the table stays at max_sensors, the real person stays present."""
    c = Clock(RadarPresenceSettings(max_sensors=16))
    fake = 0
    for _ in range(100):  # 10 s of real frames
        c.feed(at(120), 0.1, sensor="0/0")
        for _ in range(280):
            v = c.tracker.update(f"evil/{fake}", NOBODY, c.t, round(c.t * 1e9))
            assert v is None
            fake += 1
        c.idle(0.05)
    assert fake == 28_000
    assert c.states == [(IN, MOVING)]
    assert len(c.tracker.known_sensors()) <= 16
    assert c.tracker.evicted >= 28_000 - 16
    assert "0/0" not in c.tracker.stale_sensors(c.t)


def test_room_is_made_from_the_newest_one_shot_ids() -> None:
    tracker = PresenceTracker(RadarPresenceSettings(max_sensors=3))
    tracker.update("real", at(100), 0.0, 1)
    tracker.update("a", NOBODY, 0.0, 1)
    tracker.update("b", NOBODY, 0.1, 2)
    tracker.update("c", NOBODY, 0.1, 2)  # evicts "b": one frame, most recently heard
    assert tracker.known_sensors() == ["a", "c", "real"]
    tracker.update("real", at(100), 0.2, 3)  # 2 frames now
    tracker.update("a", NOBODY, 0.2, 3)  # 2 frames now
    tracker.update("d", NOBODY, 0.3, 4)  # evicts "c", the only one heard once
    assert tracker.known_sensors() == ["a", "d", "real"]
    tracker.update("e", NOBODY, 0.3, 4)  # evicts "d"
    assert tracker.known_sensors() == ["a", "e", "real"]
    assert tracker.evicted == 3


def test_when_every_sensor_is_established_the_least_recently_heard_goes() -> None:
    tracker = PresenceTracker(RadarPresenceSettings(max_sensors=2, stale_after_s=100.0))
    for i in range(12):
        tracker.update("old", NOBODY, i * 0.1, i)
        tracker.update("real", at(100), i * 0.1 + 0.05, i)
    assert tracker.established("old") and tracker.established("real")
    tracker.update("new", NOBODY, 2.0, 20)
    assert tracker.known_sensors() == ["new", "real"]


def test_a_sensor_becomes_established_during_a_flood() -> None:
    """From its very first frame, in the middle of a flood of one-shot ids."""
    tracker = PresenceTracker(RadarPresenceSettings(max_sensors=4))
    fake = 0
    t = 0.0
    for _ in range(15):
        tracker.update("real", at(120), t, round(t * 1e9))
        for _ in range(500):
            tracker.update(f"evil/{fake}", NOBODY, t, round(t * 1e9))
            fake += 1
        t += 0.1
    assert tracker.established("real")
    assert "real" in tracker.known_sensors() and tracker.presence == IN
    # Once established, even sensors sent twice cannot push it out.
    for i in range(1000):
        for _ in range(2):
            tracker.update(f"twice/{i}", NOBODY, t, round(t * 1e9))
    assert "real" in tracker.known_sensors()


def test_one_frame_stamped_in_the_far_future_does_not_stamp_later_verdicts() -> None:
    """The verdict a tick causes carries the latest frame's stamp, not the largest seen."""
    tracker = PresenceTracker(RadarPresenceSettings(absence_hold_s=1.0))
    poisoned = 2**63 - 1
    v = tracker.update("0/0", at(100), 0.0, poisoned)
    assert v is not None and v.stamp_ns == poisoned  # the frame that caused it (the
    # service replaces such stamps on arrival; here the rule alone is tested)
    t = 0.1
    while t < 3.0:
        v = tracker.update("0/0", NOBODY, t, round(t * 1e9)) or tracker.tick(t + 0.05)
        if v is not None:
            break
        t += 0.1
    assert v is not None and v.presence == OUT
    assert v.stamp_ns < 10 * 10**9


def _run_scenario(name: str, seconds: float, rules: RadarPresenceSettings | None = None) -> Clock:
    scenario = SCENARIOS[name]
    rng = random.Random(3)
    c = Clock(rules)
    t = 0.0
    while t < seconds:
        target = scenario(t, rng)
        c.feed(Reading(target.state, target.detection_cm, target.moving_cm, target.still_cm))
        t += 0.1
    return c


def test_walk_in_scenario_gives_one_visit() -> None:
    c = _run_scenario("walk-in", 20.0)
    presence = [v.presence for v in c.verdicts]
    assert presence[0] == IN and presence[-1] == OUT
    assert presence.count(OUT) == 1
    # After a (re)start with someone already on the way, the first verdict is IN.
    assert [p for i, p in enumerate(presence) if i == 0 or presence[i - 1] != p] == [IN, OUT]


def test_visit_loop_is_20_to_30_s_in_range_then_away() -> None:
    c = _run_scenario("visit", 38.0 * 2)
    edges = [(v.presence, v.stamp_ns / 1e9) for v in c.verdicts
             if v.presence == OUT or (v.target == MOVING and v.presence == IN)]
    ins = [t for p, t in edges if p == IN]
    outs = [t for p, t in edges if p == OUT]
    assert len(outs) == 2
    assert 20.0 <= outs[0] - ins[0] <= 30.0


def test_passer_by_never_in_range() -> None:
    c = _run_scenario("passer-by", 30.0)
    assert [v.presence for v in c.verdicts] == [OUT]  # the initial verdict, after the hold
    assert c.verdicts[0].stamp_ns == 0  # stamped by the first frame with nobody


def test_noisy_sensor_does_not_flap() -> None:
    c = _run_scenario("noisy", 60.0)
    assert [v.presence for v in c.verdicts].count(OUT) == 0
    assert c.verdicts[0].presence == IN


# --- angle radars (LD2450) ------------------------------------------------------------

DOOR = msgspec.convert({"name": "doorway", "mode": "ignore", "x": [2.0, 3.0], "y": [-1.0, 0.0]},
                       RadarZone)
ROOM = msgspec.convert({"name": "room", "mode": "detect", "x": [0.3, 2.5], "y": [-1.5, 1.5]},
                       RadarZone)


def seen(*targets: RadarTarget, rules: RadarPresenceSettings | None = None) -> TargetsReading:
    return read_targets(targets, rules or RadarPresenceSettings())


def test_a_report_reads_as_its_nearest_counted_target() -> None:
    far, near = radar_target(3.0, 1.0, 0.0, slot=0), radar_target(1.2, -0.5, 0.0, slot=1)
    reading = seen(far, near)
    assert reading.present and reading.nearest == near
    assert reading.distance_m == pytest.approx(1.3)
    assert (reading.ignored, reading.outside) == (0, 0)
    nobody = seen()
    assert not nobody.present and nobody.distance_m == 0.0


def test_zones_decide_which_targets_count_and_count_the_others() -> None:
    rules = RadarPresenceSettings(zones=[ROOM, DOOR])
    in_door = radar_target(2.2, -0.5)  # inside the room too: ignore wins
    beyond = radar_target(4.0, 0.0)  # outside the only detect zone
    person = radar_target(2.0, 1.0)
    reading = seen(in_door, beyond, person, rules=rules)
    assert reading.nearest == person
    assert (reading.ignored, reading.outside) == (1, 1)
    only_door = seen(in_door, rules=rules)
    assert not only_door.present and only_door.ignored == 1


@pytest.mark.parametrize(("speed", "kind"), [
    (0.0, STANDING), (0.1, STANDING), (-0.1, STANDING), (0.11, MOVING), (-0.5, MOVING),
    (1.4, MOVING)])
def test_the_kind_comes_from_the_nearest_counted_target_s_speed(
        speed: float, kind: PresenceTarget) -> None:
    """|speed| strictly above moving_speed_mps (0.1 m/s) is MOVING, either way."""
    assert seen(radar_target(1.0, 0.0, speed)).kind == kind


def test_only_the_nearest_target_s_speed_decides() -> None:
    walker_far, stander_near = radar_target(1.8, 0.0, 1.2), radar_target(1.0, 0.0, 0.0)
    assert seen(walker_far, stander_near).kind == STANDING
    in_door = radar_target(2.2, -0.5, 1.2)  # ignored: its speed does not count either
    assert seen(in_door, radar_target(1.5, 0.5, 0.0),
                rules=RadarPresenceSettings(zones=[DOOR])).kind == STANDING


def test_moving_speed_is_a_rule() -> None:
    walk = radar_target(1.0, 0.0, 0.3)
    assert seen(walk).kind == MOVING
    assert seen(walk, rules=RadarPresenceSettings(moving_speed_mps=0.5)).kind == STANDING


def test_ld2450_enters_on_the_first_report_in_range_and_leaves_after_the_hold() -> None:
    c = Clock(RadarPresenceSettings(range_m=2.0, exit_margin_m=0.3, absence_hold_s=1.0))
    c.feed(seen(radar_target(3.0, 0.0, -1.0)), 1.0)
    assert c.verdicts == []
    c.feed(seen(radar_target(1.2, 1.6, -1.0)))  # exactly 2.0 m: in range
    assert c.states == [(IN, MOVING)]
    assert c.verdicts[0].distance_m == 2.0
    for x in [2.1, 2.25, 1.9, 2.29] * 5:  # within the exit margin: stays
        c.feed(seen(radar_target(x, 0.0, -1.0)))
    assert c.states == [(IN, MOVING)]
    c.feed(seen(), 0.9)  # nobody for less than the hold
    assert c.states == [(IN, MOVING)]
    c.feed(seen(), 0.2)
    assert [s for s, _ in c.states] == [IN, OUT]
    assert c.verdicts[-1].distance_m == 0.0


def test_ld2450_standing_needs_to_last_like_an_ld2410_kind() -> None:
    c = Clock(RadarPresenceSettings(target_hold_s=1.0))
    c.feed(seen(radar_target(1.0, 0.0, 0.8)))
    for _ in range(10):  # stops for a moment, walks on
        c.feed(seen(radar_target(1.0, 0.0, 0.0)), 0.5)
        c.feed(seen(radar_target(1.0, 0.0, 0.8)), 0.2)
    assert c.states == [(IN, MOVING)]
    c.feed(seen(radar_target(1.0, 0.0, 0.0)), 1.2)
    assert c.states == [(IN, MOVING), (IN, STANDING)]


def test_a_target_in_an_ignore_zone_makes_no_presence() -> None:
    """The TV in the doorway zone, 2.2 m... with range 3 m: never IN_RANGE;
    a person elsewhere at the same distance is."""
    rules = RadarPresenceSettings(range_m=3.0, absence_hold_s=0.5, zones=[DOOR])
    c = Clock(rules)
    tv = radar_target(2.2, -0.5, 0.4)
    c.feed(read_targets([tv], rules), 2.0)
    assert c.states == [(OUT, MOVING)]
    c.feed(read_targets([tv, radar_target(2.2, 0.5)], rules))
    assert c.states == [(OUT, MOVING), (IN, STANDING)]


def test_zones_changed_live_apply_to_the_next_report() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.3))
    target = radar_target(1.5, -0.2)
    c.feed(read_targets([target], c.tracker.rules))
    assert c.states == [(IN, STANDING)]
    c.tracker.rules = RadarPresenceSettings(absence_hold_s=0.3, zones=[
        msgspec.convert({"name": "here", "mode": "ignore", "x": [1.0, 2.0], "y": [-1.0, 1.0]},
                        RadarZone)])
    c.feed(read_targets([target], c.tracker.rules), 0.5)
    assert c.states == [(IN, STANDING), (OUT, STANDING)]


def test_an_ld2450_report_with_nobody_is_fresh_and_a_silent_one_is_stale() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.5, stale_after_s=1.0))
    c.feed(seen(radar_target(1.0, 0.0)), sensor="0/1")
    c.idle(3.0)  # silent: its person is neither kept nor forgotten by the hold
    assert c.tracker.stale_sensors(c.t) == ["0/1"]
    assert c.states == [(IN, STANDING)]
    c.feed(seen(), 0.6, sensor="0/1")  # back, seeing nobody
    assert c.states == [(IN, STANDING), (OUT, STANDING)]
    assert c.tracker.stale_sensors(c.t) == []


# --- both models at once ----------------------------------------------------------------


def test_mixed_sensors_in_range_when_any_says_so() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.5))
    for _ in range(10):  # LD2410 sees nobody, the LD2450 nobody in range
        c.feed(NOBODY, sensor="0/0")
        c.feed(seen(radar_target(3.0, 0.0)), sensor="0/1")
    assert c.states == [(OUT, MOVING)]
    c.feed(seen(radar_target(1.5, 0.0, 0.0)), sensor="0/1")  # the LD2450 alone
    assert c.states[-1] == (IN, STANDING)
    for _ in range(5):  # the LD2450 loses them, the LD2410 has them: still IN
        c.feed(seen(), sensor="0/1")
        c.feed(at(140, 1), sensor="0/0")
    assert [s for s, _ in c.states] == [OUT, IN]
    for _ in range(10):  # both see nobody for the hold
        c.feed(seen(), sensor="0/1")
        c.feed(NOBODY, sensor="0/0")
    assert [s for s, _ in c.states] == [OUT, IN, OUT]


def test_mixed_sensors_the_nearest_decides_distance_and_kind() -> None:
    tracker = PresenceTracker(RadarPresenceSettings())
    tracker.update("0/0", at(180, 2), 0.0, 1)  # LD2410: someone still at 1.8 m
    v = tracker.update("0/1", seen(radar_target(0.9, 0.3, 0.6)), 0.0, 2)
    assert v is None  # already IN_RANGE (STANDING), the kind change must last
    assert tracker.presence == IN and tracker.target == STANDING
    v = tracker.update("0/1", seen(radar_target(0.9, 0.3, 0.6)), 1.1, 3)
    assert v == Verdict(IN, MOVING, round(0.9487, 3), 3)


def test_an_ld2410_ignores_the_zones() -> None:
    """It has no position: its distance counts wherever the person stands."""
    everywhere = msgspec.convert({"name": "all", "mode": "ignore", "x": [-20, 20],
                                  "y": [-20, 20]}, RadarZone)
    c = Clock(RadarPresenceSettings(zones=[everywhere]))
    c.feed(at(120), sensor="0/0")
    assert c.states == [(IN, MOVING)]


def test_a_sensor_switching_model_keeps_its_entry() -> None:
    c = Clock(RadarPresenceSettings(absence_hold_s=0.5))
    c.feed(at(120), sensor="0/0")
    c.feed(seen(), 0.6, sensor="0/0")  # the same sensor now sends LD2450 reports
    assert c.tracker.known_sensors() == ["0/0"]
    assert [s for s, _ in c.states] == [IN, OUT]
