"""The play_sound action's goal state machine (pure: no Zenoh, no clock of its own).

A goal names a configured sound, `say:<text>` to speak any text
(`messages.spoken_text` is the rule) or `file:<path>` to play a file
(`messages.sound_file`; whether the file may be played is the player's
sandbox, so a file outside it ends ABORTED with the player's refusal).
It is ACCEPTED when its reply says so, PLAYING once the player confirmed
it started (progress = elapsed / the duration the player announced), and
ends SUCCEEDED (the device became free after the sound's length),
CANCELED (cancel request, preempted by a newer goal, or stopped from
outside before its end) or ABORTED (the player refused or did not answer).
One goal is active at a time; `policy` decides what a new goal does
meanwhile: "preempt" ends the active one as CANCELED, "refuse" answers
accepted=false.

Every method returns the status messages to publish, in order, so the
service adapter only publishes them.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

from buddybot.contract import messages as m
from buddybot.contract.messages import TERMINAL_GOAL_STATES, GoalState
from buddybot.runtime import limits

END_TOLERANCE_S = 0.25
"""A device that becomes free this much before the announced end still means
the sound played through (the last period is handed over early)."""
LATE_GRACE_S = 1.0
"""How long past its end a goal may wait for the device-free sample."""


@dataclass
class Goal:
    goal_id: str
    sound: str
    state: GoalState = "ACCEPTED"
    message: str = ""
    duration_s: float | None = None
    started_at: float | None = None
    asked_ns: int | None = None
    """When the player was asked to play it (wall clock, ns): a "free" stamped
    earlier is the player's state from before this goal, not its end."""
    progress: float = 0.0

    @property
    def terminal(self) -> bool:
        return self.state in TERMINAL_GOAL_STATES

    def status(self) -> m.PlaySoundStatus:
        return m.PlaySoundStatus(goal_id=self.goal_id, state=self.state,
                                 progress=self.progress, message=self.message,
                                 stamp_ns=m.now_ns())


@dataclass
class Decision:
    """The answer to a goal request and the statuses it causes."""

    reply: m.PlaySoundReply
    statuses: list[m.PlaySoundStatus] = field(default_factory=list)

    @property
    def accepted(self) -> bool:
        return self.reply.accepted


@dataclass
class CancelResult:
    reply: m.TriggerReply
    statuses: list[m.PlaySoundStatus] = field(default_factory=list)
    stop_player: bool = False


class GoalBook:
    """All goals of one action server: the active one and recent finished ones."""

    def __init__(self, sounds: Collection[str], policy: str = "preempt",
                 history: int = 64) -> None:
        if policy not in ("preempt", "refuse"):
            raise ValueError(f"unknown busy policy {policy!r}")
        self.sounds = set(sounds)
        self.policy = policy
        self.active: Goal | None = None
        self._recent: limits.BoundedDict[str, Goal] = limits.BoundedDict(history)
        """Finished goals (for a late cancel's answer); refused goals are never kept."""

    def get(self, goal_id: str) -> Goal | None:
        if self.active is not None and self.active.goal_id == goal_id:
            return self.active
        return self._recent.get(goal_id)

    def _end(self, goal: Goal, state: GoalState, message: str) -> m.PlaySoundStatus:
        goal.state, goal.message = state, message
        if state == "SUCCEEDED":
            goal.progress = 1.0
        if self.active is goal:
            self.active = None
        self._recent[goal.goal_id] = goal
        return goal.status()

    @property
    def tracked(self) -> int:
        """Goals held in memory: the active one and the bounded finished history."""
        return len(self._recent) + (self.active is not None)

    # -- requests --

    def request(self, goal_id: str, sound: str, *, player_present: bool,
                player_busy: bool = False) -> Decision:
        """Accept or refuse a goal; an accepted goal is then to be played."""
        def refuse(why: str) -> Decision:
            return Decision(m.PlaySoundReply(goal_id=goal_id, accepted=False, message=why))

        if sound not in self.sounds:
            try:
                named = m.spoken_text(sound) or m.sound_file(sound)
            except ValueError as exc:
                return refuse(str(exc))
            if named is None:
                known = ", ".join(sorted(self.sounds)) or "none"
                return refuse(f"unknown sound {limits.clip(sound)!r} (configured: "
                              f"{limits.clip(known)}; or {m.TTS_PREFIX}TEXT to speak TEXT, "
                              f"{m.FILE_PREFIX}PATH to play a file of the sound folders)")
        if not player_present:
            return refuse("the audio player is not running")
        statuses = []
        busy = self.active is not None or player_busy
        if busy and self.policy == "refuse":
            what = f"goal {self.active.goal_id} ({self.active.sound})" if self.active else (
                "another sound")
            return refuse(f"busy: {what} is playing (busy_policy = refuse)")
        if self.active is not None:
            statuses.append(self._end(self.active, "CANCELED", f"preempted by goal {goal_id}"))
        goal = Goal(goal_id=goal_id, sound=sound)
        self.active = goal
        statuses.append(goal.status())
        return Decision(m.PlaySoundReply(goal_id=goal_id, accepted=True,
                                         message=f"playing {sound}"), statuses)

    def should_play(self, goal_id: str) -> bool:
        """Whether an accepted goal is still waiting to be handed to the player."""
        return self.active is not None and self.active.goal_id == goal_id and (
            self.active.state == "ACCEPTED")

    def started(self, goal_id: str, duration_s: float | None, asked_at: float,
                asked_ns: int | None = None) -> list[m.PlaySoundStatus]:
        """The player confirmed playback: ACCEPTED -> PLAYING. The sound's time
        counts from `asked_at`, when the player was asked (monotonic): it began
        between that and the reply, and a reply slowed by a busy machine must
        not make a sound that played through look cut short."""
        goal = self.active
        if goal is None or goal.goal_id != goal_id or goal.state != "ACCEPTED":
            return []
        goal.state, goal.duration_s, goal.started_at = "PLAYING", duration_s, asked_at
        goal.asked_ns = asked_ns
        goal.message = "" if duration_s is None else f"{duration_s:.3f} s"
        return [goal.status()]

    def failed(self, goal_id: str, message: str) -> list[m.PlaySoundStatus]:
        """The player refused or did not answer: ABORTED with its reason."""
        goal = self.active
        if goal is None or goal.goal_id != goal_id:
            return []
        return [self._end(goal, "ABORTED", message)]

    def device_free(self, now: float, stamp_ns: int | None = None) -> list[m.PlaySoundStatus]:
        """The player's device became free: the playing goal ended. A sample
        stamped before the player was asked (a player that just started sends
        its latched "free" late) says nothing about this goal."""
        goal = self.active
        if goal is None or goal.state != "PLAYING":
            return []
        if stamp_ns is not None and goal.asked_ns is not None and stamp_ns < goal.asked_ns:
            return []
        elapsed = now - (goal.started_at or now)
        if goal.duration_s is not None and elapsed < goal.duration_s - END_TOLERANCE_S:
            return [self._end(goal, "CANCELED",
                              f"playback stopped outside the action after {elapsed:.2f} s")]
        return [self._end(goal, "SUCCEEDED", "")]

    def cancel(self, goal_id: str) -> CancelResult:
        """Cancel the active goal (the player must then be stopped)."""
        goal = self.active
        if goal is not None and goal.goal_id == goal_id:
            status = self._end(goal, "CANCELED", "canceled on request")
            return CancelResult(m.TriggerReply(success=True, message="canceled"), [status],
                                stop_player=True)
        old = self._recent.get(goal_id)
        if old is not None:
            return CancelResult(m.TriggerReply(
                success=False, message=f"goal {goal_id} already ended ({old.state})"))
        return CancelResult(m.TriggerReply(success=False, message=f"unknown goal {goal_id!r}"))

    def player_lost(self, message: str = "the audio player stopped running"
                    ) -> list[m.PlaySoundStatus]:
        """The player process (or the instance playing the goal) went away: the
        active goal cannot finish."""
        if self.active is None:
            return []
        return [self._end(self.active, "ABORTED", message)]

    def tick(self, now: float, device_free: bool | None = None) -> list[m.PlaySoundStatus]:
        """Progress of the playing goal (capped below 1 until the device is free).

        A device already free well after the announced end means the "free"
        sample raced ahead of the player's reply: the goal succeeded.
        """
        goal = self.active
        if goal is None or goal.state != "PLAYING" or goal.started_at is None:
            return []
        elapsed = now - goal.started_at
        if (device_free and goal.duration_s is not None
                and elapsed > goal.duration_s + LATE_GRACE_S):
            return [self._end(goal, "SUCCEEDED", "")]
        if goal.duration_s:
            goal.progress = max(0.0, min(0.99, elapsed / goal.duration_s))
        return [goal.status()]
