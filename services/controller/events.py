"""The controller's inbox vocabulary: what Zenoh callbacks and the sound thread
tell the decision thread.

Each event is a small frozen dataclass, and `Event` is their union, so the
decision thread dispatches with an exhaustive `match` that a type checker
verifies: a new event that nobody handles is a type error (`assert_never`),
not a string tag silently falling through an if-chain. Events are frozen
because they cross threads: the poster must not change one after handing it
over.

They live apart from `behaviour.py` because they are the service's plumbing
(who posted what), while `Behaviour` keeps its plain method API (`presence`,
`sound_reply`, ...) that the pure tests drive directly. Faces are not events:
a face is decided in its Zenoh callback (the gaze's latency path), so a fast
camera neither waits for the decision thread nor fills the inbox.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class PresenceChanged:
    """Radar presence (latched): someone IN_RANGE or not."""

    in_range: bool


@dataclass(frozen=True, slots=True)
class DeviceFree:
    """`audio/device_free`: the player is idle (it may be busy with another program)."""

    free: bool


@dataclass(frozen=True, slots=True)
class SoundStatus:
    """`audio/play_sound/status`; `age_s` is how old the status is (None: unknown),
    which matters for a latched status replayed to a restarted controller."""

    goal_id: str
    state: str
    age_s: float | None


@dataclass(frozen=True, slots=True)
class GoalReply:
    """The answer to a `PlaySound` command; a failed call is `accepted=False, goal_id=""`."""

    request: int
    accepted: bool
    goal_id: str


@dataclass(frozen=True, slots=True)
class CancelReply:
    """The answer to a `CancelSound` command; a failed call is `success=False`."""

    goal_id: str
    success: bool


Event = PresenceChanged | DeviceFree | SoundStatus | GoalReply | CancelReply
