"""The eyes' own motion, decided once for the whole face (pure: services/eyes/motion.py).

Time is simulated: the scheduler is ticked at its own `next_due_ms()` (as
the renderer's timer does), with a seeded random generator.
"""

from __future__ import annotations

import itertools
import math
import random

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.eyes import motion, wire
from buddybot.eyes.motion import MotionConfig, MotionEvent, MotionScheduler
from buddybot.eyes.renderer import motion_config
from buddybot.eyes.settings import EyeRendererSettings

A = m.ExpressionAction
T0 = 1_700_000_000_000.0   # a server clock reading, ms since the epoch


def make(seed: int = 1, config: MotionConfig | None = None,
         expression: int = A.EYE_AWAKE) -> MotionScheduler:
    return MotionScheduler(config or MotionConfig(), random.Random(seed), T0, expression)


def run(sched: MotionScheduler, start_ms: float, end_ms: float,
        directions: list[tuple[float, float, float]] = ()) -> list[MotionEvent]:
    """Tick at every due time (and feed `directions` (t, yaw, pitch) at theirs)."""
    pending = sorted(directions)
    events: list[MotionEvent] = []
    now = start_ms
    while True:
        due = min(sched.next_due_ms(), pending[0][0] if pending else math.inf)
        if due > end_ms:
            return events
        now = max(now, due)
        if pending and pending[0][0] <= now:
            _t, yaw, pitch = pending.pop(0)
            events += sched.set_direction(yaw, pitch, now)
        events += sched.tick(now)


def of(events: list[MotionEvent], kind: str, purpose: str | None = None) -> list[MotionEvent]:
    return [e for e in events if e.kind == kind
            and (purpose is None or e.params.get("purpose") == purpose)]


def test_main_sequence_grows_with_amplitude_within_20_to_200_ms() -> None:
    amplitudes = [0.0, 0.5, 1, 2, 5, 10, 20, 40, 60, 80, 120]
    durations = [motion.saccade_duration_ms(a) for a in amplitudes]
    assert durations == sorted(durations)
    assert all(20.0 <= d <= 200.0 for d in durations)
    assert 20.0 <= motion.saccade_duration_ms(1.5) <= 30.0        # small: 20-30 ms
    assert 60.0 <= motion.saccade_duration_ms(20.0) <= 70.0       # 2.2 ms/deg + 21 ms
    assert motion.saccade_duration_ms(80.0) == pytest.approx(197.0)
    assert motion.saccade_duration_ms(500.0) == 200.0
    assert motion.saccade_duration_ms(-10.0) == motion.saccade_duration_ms(10.0)


def test_every_saccade_follows_the_main_sequence() -> None:
    sched = make(3, expression=A.EYE_LOOK_RANDOM)
    events = run(sched, T0, T0 + 60_000)
    saccades = of(events, "saccade")
    assert len(saccades) > 50
    for e in saccades:
        p = e.params
        amplitude = math.hypot(float(p["yaw"]) - float(p["from_yaw"]),
                               float(p["pitch"]) - float(p["from_pitch"]))
        assert p["amplitude_deg"] == pytest.approx(amplitude)
        assert e.duration_ms == pytest.approx(motion.saccade_duration_ms(amplitude))
    # Each saccade starts where the previous one ended: one continuous path.
    for a, b in itertools.pairwise(saccades):
        assert (b.params["from_yaw"], b.params["from_pitch"]) == (
            a.params["yaw"], a.params["pitch"])


def test_spontaneous_blinks_every_few_seconds() -> None:
    sched = make(5)
    blinks = of(run(sched, T0, T0 + 120_000), "blink")
    gaps = [b.start_ms - a.start_ms for a, b in itertools.pairwise(blinks)]
    assert len(blinks) > 15
    assert all(2500.0 <= g <= 6500.0 for g in gaps), gaps
    assert max(gaps) - min(gaps) > 1500.0                        # random, not a metronome
    for b in blinks:
        assert b.params["cause"] == "spontaneous"
        assert b.duration_ms == b.params["close_ms"] + b.params["open_ms"]
        assert 50.0 <= float(b.params["close_ms"]) <= 70.0
        assert float(b.params["open_ms"]) > float(b.params["close_ms"])


def test_blink_interval_follows_the_config_and_a_live_change() -> None:
    sched = make(2, MotionConfig(blink_interval_min_ms=500, blink_interval_max_ms=800))
    blinks = of(run(sched, T0, T0 + 10_000), "blink")
    gaps = [b.start_ms - a.start_ms for a, b in itertools.pairwise(blinks)]
    assert gaps and all(500.0 <= g <= 800.0 for g in gaps), gaps
    sched.configure(MotionConfig(blink_interval_min_ms=3000, blink_interval_max_ms=3000),
                    T0 + 10_000)
    later = of(run(sched, T0 + 10_000, T0 + 30_000), "blink")
    assert [b.start_ms - a.start_ms for a, b in itertools.pairwise(later)] == pytest.approx(
        [3000.0] * (len(later) - 1))


def test_events_start_lead_ms_after_they_are_decided() -> None:
    sched = make(4, MotionConfig(lead_ms=75.0))
    now = sched.next_due_ms()
    events = sched.tick(now)
    assert events and all(e.start_ms == pytest.approx(now + 75.0) for e in events)


def test_a_large_gaze_shift_brings_a_blink_a_small_or_slow_one_does_not() -> None:
    config = MotionConfig(blink_interval_min_ms=60_000, blink_interval_max_ms=60_000)
    sched = make(6, config)
    t = T0 + 1000
    assert of(sched.set_direction(0.0, 0.0, t), "blink") == []
    assert of(sched.set_direction(10.0, 0.0, t + 33), "blink") == []          # 10 deg
    shifted = of(sched.set_direction(-15.0, 5.0, t + 66), "blink")            # ~25 deg
    assert len(shifted) == 1 and shifted[0].params["cause"] == "gaze"
    assert shifted[0].start_ms == pytest.approx(t + 66 + config.lead_ms)
    # A slow pursuit over 40 degrees (10 deg/s at 30 Hz) is no gaze shift.
    events = []
    for i in range(120):
        events += sched.set_direction(-15.0 + i / 3, 5.0, t + 3000 + i * 33.3)
    assert of(events, "blink") == []
    # A jump after a quiet spell is one.
    assert len(of(sched.set_direction(-30.0, 0.0, t + 20_000), "blink")) == 1


def test_drowsy_blinks_are_slower_and_sleep_stops_all_motion() -> None:
    sched = make(7, expression=A.EYE_SLEEPY)
    drowsy = of(run(sched, T0, T0 + 30_000), "blink")
    assert drowsy and all(b.params["cause"] == "drowsy" for b in drowsy)
    assert min(b.duration_ms for b in drowsy) > 1.8 * (60 + 160)

    sched = make(8, expression=A.EYE_LOOK_RANDOM)
    run(sched, T0, T0 + 5_000)
    at_sleep = sched.set_expression(A.EYE_SLEEP, T0 + 5_000)
    # At most one saccade back to rest as the lids close, then nothing at all.
    assert [e.params["purpose"] for e in at_sleep] in ([], ["rest"])
    assert sched.offset == (0.0, 0.0)
    assert sched.next_due_ms() == math.inf
    asleep = run(sched, T0 + 5_000, T0 + 120_000,
                 [(T0 + 10_000, 30.0, 0.0), (T0 + 10_100, -30.0, 10.0)])
    assert asleep == [] and sched.tick(T0 + 200_000) == []
    # Waking plans blinks and saccades again.
    sched.set_expression(A.EYE_AWAKE, T0 + 200_000)
    woke = run(sched, T0 + 200_000, T0 + 220_000)
    assert of(woke, "blink") and of(woke, "saccade")


def test_look_random_is_look_hold_look_back() -> None:
    config = MotionConfig(max_yaw_deg=40.0, max_pitch_deg=30.0)
    sched = make(9, config, A.EYE_LOOK_RANDOM)
    saccades = of(run(sched, T0, T0 + 60_000), "saccade")
    sequence = [e for e in saccades if e.params["purpose"] in ("glance", "return")]
    assert len(sequence) >= 20
    pairs = list(zip(sequence[::2], sequence[1::2], strict=False))
    for look, back in pairs:
        assert (look.params["purpose"], back.params["purpose"]) == ("glance", "return")
        # Somewhere in the room, well beyond fixational jitter ...
        assert look.params["amplitude_deg"] >= 8.0
        assert abs(float(look.params["yaw"])) <= 0.7 * 40.0 + 1e-9
        assert abs(float(look.params["pitch"])) <= 0.5 * 30.0 + 1e-9
        # ... held 0.6-1.5 s once there, then back to where it came from.
        hold = back.start_ms - look.end_ms
        assert 600.0 <= hold <= 1500.0, hold
        assert (back.params["yaw"], back.params["pitch"]) == (
            look.params["from_yaw"], look.params["from_pitch"])
    # No fixational jitter in the middle of a glance.
    for look, back in pairs:
        assert not [e for e in saccades if look.start_ms < e.start_ms < back.start_ms]


def test_large_glances_blink_and_idle_motion_is_small() -> None:
    sched = make(10, expression=A.EYE_LOOK_RANDOM)
    events = run(sched, T0, T0 + 60_000)
    big = [e for e in of(events, "saccade", "glance") if e.params["amplitude_deg"] >= 18.0]
    blinks = of(events, "blink")
    # Each comes with a blink: its own, or one that had just started.
    assert big and all(any(0 <= e.start_ms - b.start_ms < motion.BLINK_REFRACTORY_MS
                           for b in blinks) for e in big)
    assert any(b.params["cause"] == "gaze" for b in blinks)

    idle = run(make(11), T0, T0 + 120_000)
    for e in of(idle, "saccade"):
        size = math.hypot(float(e.params["yaw"]), float(e.params["pitch"]))
        limit = 12.0 if e.params["purpose"] == "glance" else 3.7
        assert size <= limit + 1e-9, e
    assert of(idle, "saccade", "glance") and of(idle, "saccade", "return")
    assert all(b.params["cause"] == "spontaneous" for b in of(idle, "blink"))


def test_following_someone_keeps_the_gaze_steady_and_ends_a_glance() -> None:
    sched = make(12)
    events = run(sched, T0, T0 + 30_000)
    glances = of(events, "saccade", "glance")
    assert glances
    # Mid-glance, someone to follow: the eyes look back at once.
    look_start = glances[-1].start_ms - sched.config.lead_ms
    sched = make(12)
    run(sched, T0, look_start)
    assert sched.offset != (0.0, 0.0)
    back = sched.set_direction(5.0, 0.0, look_start + 100)
    assert [e.params["purpose"] for e in of(back, "saccade")][:1] == ["return"]
    # While following (30 Hz), fixational saccades stay within a degree and no glance.
    follow = [(look_start + 200 + i * 33.3, 5.0, 0.0) for i in range(600)]
    tracked = run(sched, look_start + 200, look_start + 200 + 600 * 33.3, follow)
    assert of(tracked, "saccade", "glance") == []
    for e in of(tracked, "saccade", "fixation"):
        assert abs(float(e.params["yaw"])) <= 1.0 and abs(float(e.params["pitch"])) <= 0.7


def test_same_seed_same_events() -> None:
    def script(seed: int) -> list[MotionEvent]:
        sched = make(seed)
        events = run(sched, T0, T0 + 20_000, [(T0 + 5000, 30.0, 0.0)])
        events += sched.set_expression(A.EYE_LOOK_RANDOM, T0 + 20_000)
        events += run(sched, T0 + 20_000, T0 + 40_000)
        events += sched.set_expression(A.EYE_SLEEPY, T0 + 40_000)
        return events + run(sched, T0 + 40_000, T0 + 60_000)

    assert script(42) == script(42)
    assert script(42) != script(43)


def test_motion_events_on_the_wire() -> None:
    event = MotionEvent(kind="blink", start_ms=T0, duration_ms=220.0,
                        params={"close_ms": 60.0, "open_ms": 160.0, "cause": "gaze"})
    data = msgspec.json.decode(wire.encode("motion", event))
    assert data == {"topic": "motion", "msg": {
        "kind": "blink", "start_ms": T0, "duration_ms": 220.0,
        "params": {"close_ms": 60.0, "open_ms": 160.0, "cause": "gaze"}}}
    state = wire.LatestState()
    for kind, start in (("blink", 1.0), ("saccade", 2.0), ("blink", 3.0)):
        state.put(wire.motion_slot(kind), wire.encode(
            "motion", MotionEvent(kind=kind, start_ms=start, duration_ms=1.0, params={})))
    kept = [msgspec.json.decode(t)["msg"]["start_ms"] for t in state.snapshot()]
    assert kept == [2.0, 3.0]      # the newest of each kind: what a late page joins


@pytest.mark.parametrize("text, t0", [
    ('{"topic":"ping","msg":{"t0":123.5}}', 123.5),
    ('{"topic":"ping","msg":{"t0":7}}', 7.0),
    ('{"topic":"ping","msg":{"t0":true}}', None),
    ('{"topic":"ping","msg":{"t0":"1"}}', None),
    ('{"topic":"ping","msg":[1]}', None),
    ('{"topic":"pong","msg":{"t0":1}}', None),
    ("not json", None), ("[]", None), ("", None),
    ('{"topic":"ping","msg":{"t0":1, "pad":"' + "x" * 300 + '"}}', None),
])
def test_clock_ping_parsing(text: str, t0: float | None) -> None:
    assert wire.parse_ping(text) == t0


def test_motion_settings_reach_the_scheduler_and_are_checked() -> None:
    s = msgspec.convert({"blink_interval_min_s": 0.5, "blink_interval_max_s": 0.8,
                         "gaze_blink_deg": 25, "motion_lead_ms": 80}, EyeRendererSettings)
    config = motion_config(s)
    assert (config.blink_interval_min_ms, config.blink_interval_max_ms,
            config.gaze_blink_deg, config.lead_ms) == (500.0, 800.0, 25.0, 80.0)
    # A longest interval below the shortest is one fixed interval, not an error (each
    # field can be set on its own, live, without the other one in between).
    fixed = motion_config(msgspec.convert({"blink_interval_min_s": 5, "blink_interval_max_s": 3},
                                          EyeRendererSettings))
    sched = MotionScheduler(fixed, random.Random(1), 0.0)
    assert sched._blink_interval() == 5000.0
    with pytest.raises(msgspec.ValidationError, match=r">= 0\.3"):
        msgspec.convert({"blink_interval_min_s": 0.1}, EyeRendererSettings)


def test_the_hub_feeds_its_scheduler_and_keeps_the_motion_for_late_pages() -> None:
    """The renderer's glue, without processes: bus samples reach the scheduler,
    its events land in the state a (re)connecting page gets, a live settings
    change reaches it."""
    from buddybot.eyes.renderer import Hub, now_ms

    hub = Hub(wire.Hello(iris_color="#000000", max_yaw_deg=40.0, max_pitch_deg=30.0,
                         server_id="t"))
    sched = MotionScheduler(MotionConfig(), random.Random(1), now_ms())
    hub.start_motion(sched)
    hub.publish(m.EyesDirection(stamp_ns=1, yaw=0.0, pitch=0.0))
    hub.publish(m.EyesDirection(stamp_ns=2, yaw=30.0, pitch=0.0))   # a large shift
    page = hub.join("left")
    sent = [msgspec.json.decode(t) for t in page.outbox.take()]
    blink = [x["msg"] for x in sent if x["topic"] == "motion" and x["msg"]["kind"] == "blink"]
    assert len(blink) == 1 and blink[0]["params"]["cause"] == "gaze"
    assert blink[0]["start_ms"] > now_ms()                  # still ahead: sent early
    hub.publish(m.ScreenExpression(stamp_ns=3, action=A.EYE_SLEEP))
    assert sched.expression == A.EYE_SLEEP and sched.next_due_ms() == math.inf
    hub.apply(msgspec.convert({"blink_interval_min_s": 1.0, "blink_interval_max_s": 2.0},
                              EyeRendererSettings))
    assert sched.config.blink_interval_max_ms == 2000.0
