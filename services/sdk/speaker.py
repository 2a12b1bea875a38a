"""The speaker: sounds played through the `audio/play_sound` action.

A goal names a sound of `[audio.sounds]`, `say:<text>` to speak any text,
or `file:<path>` to play a file of the player's sound folders (docs/design.md
4.6); its reply comes at once (accepted, or refused with the reason), its
progress on the latched `audio/play_sound/status`. `SoundHandle` follows one
goal to its final state. `goal_sound` (pure) is how `play()` tells a name
from a file.

Only the player knows its sound folders, so a file goal is accepted by the
action and judged by the player's sandbox when it is handed over: `play()`
waits for that answer (the goal PLAYING or ended) and raises `Refused` with
the player's reason when the goal ended ABORTED, as it does for a name the
action refuses.

A program that holds no "audio" lease gets one for the sound's length
(released when the sound ends), so the controller's greeting does not talk
over it, and an operator holding the speaker refuses it. Without an
eyes driver there is nobody to share the speaker with: the sound plays.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
from collections.abc import Callable, Generator
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.handles import Subscription
from buddybot.runtime.limits import BoundedDict
from buddybot.runtime.node import Node
from buddybot.sdk.actions import ActionLimit, Actuator
from buddybot.sdk.calls import call
from buddybot.sdk.errors import NoService, Refused, TimedOut
from buddybot.sdk.leases import Lease, LeaseTable
from buddybot.sdk.watch import Watch, Watchers

log = logging.getLogger("buddybot.sdk")

WAIT_S = 120.0
"""How long `wait()` and `await handle` wait for a sound's end by default."""

Sound = str | os.PathLike[str]
"""What `play()` takes: a sound name, `say:<text>`, `file:<path>`, or a path."""


def goal_sound(sound: Sound) -> str:
    """The `PlaySound.sound` for what a program passed to `play()`.

    A path object (`Path("chime.wav")`), or a str holding a "/" or ending in
    an audio suffix (.wav .flac .mp3 .ogg .oga, any case), names a file:
    `file:<path>`, relative to the player's sound folders or absolute. A str
    already starting with `say:` or `file:` is kept; any other str is a name
    of `[audio.sounds]`. ValueError for anything else, or for a goal that is
    not 1..256 characters or a malformed `file:`/`say:` goal.
    """
    if isinstance(sound, os.PathLike | PurePath):
        path = os.fspath(sound)
        if not isinstance(path, str):
            raise ValueError(f"a sound file is named by a str path, not {sound!r}")
        goal = m.FILE_PREFIX + path
    elif isinstance(sound, str):
        if sound.startswith((m.TTS_PREFIX, m.FILE_PREFIX)):
            goal = sound
        elif "/" in sound or sound.lower().endswith(m.AUDIO_SUFFIXES):
            goal = m.FILE_PREFIX + sound
        else:
            goal = sound
    else:
        raise ValueError(f"play() takes a sound name or a file path, not {sound!r}")
    if not 1 <= len(goal) <= 256:
        raise ValueError(f"a sound is a name or file of 1 to 256 characters, not {goal!r}")
    m.spoken_text(goal)
    m.sound_file(goal)
    return goal


@dataclass(frozen=True, slots=True)
class GoalStatus:
    """One status of any goal on `audio/play_sound/status` (`on_status`)."""

    goal_id: str
    state: str
    """ACCEPTED, PLAYING, SUCCEEDED, CANCELED or ABORTED."""
    message: str
    stamp_ns: int
    """When the player published it (a restarted program gets the last one, latched)."""


class SoundHandle:
    """One sound being played: `state`, `wait()`, `cancel()`, `await handle`.

    `state` goes ACCEPTED -> PLAYING -> SUCCEEDED, CANCELED or ABORTED
    (`message` says why for the last two)."""

    def __init__(self, speaker: Speaker, goal_id: str, sound: str,
                 lease: Lease | None = None) -> None:
        self._speaker = speaker
        self.goal_id = goal_id
        self.sound = sound
        self.lease = lease
        """The "audio" lease taken for this sound alone, released at its end."""
        self.state: str = "ACCEPTED"
        self.message = ""
        self._ended = threading.Event()
        self._started = threading.Event()
        """Set once the goal left ACCEPTED: the player started it, or it ended."""

    @property
    def done(self) -> bool:
        return self._ended.is_set()

    def update(self, status: m.PlaySoundStatus) -> None:
        if self._ended.is_set():
            return
        self.state, self.message = status.state, status.message
        if status.state != "ACCEPTED":
            self._started.set()
        if status.state in m.TERMINAL_GOAL_STATES:
            self._ended.set()
            if self.lease is not None:
                release_quietly(self.lease)

    def wait(self, timeout: float = WAIT_S) -> str:
        """The final state, once reached; TimedOut after `timeout` s."""
        if not self._ended.wait(timeout):
            raise TimedOut(f"sound {self.sound!r} (goal {self.goal_id}) still {self.state} "
                           f"after {timeout:g} s")
        return self.state

    def started(self, timeout: float) -> str:
        """The state once the goal left ACCEPTED (PLAYING or a final state);
        TimedOut after `timeout` s."""
        if not self._started.wait(timeout):
            raise TimedOut(f"sound {self.sound!r} (goal {self.goal_id}) not started "
                           f"after {timeout:g} s")
        return self.state

    def cancel(self, timeout: float | None = None) -> str:
        """Stop the sound; its final state (CANCELED, or how it ended first)."""
        limit = self._speaker.timeout if timeout is None else timeout
        if not self.done:
            self._speaker.cancel(self.goal_id, limit)
        return self.wait(limit)

    def __await__(self) -> Generator[Any, None, str]:
        return asyncio.to_thread(self.wait).__await__()

    def __repr__(self) -> str:
        return f"SoundHandle({self.sound!r}, goal {self.goal_id}, {self.state})"


class Speaker(Actuator):
    """Goals to `audio/play_sound` (one token of the action limit each), and
    their statuses routed to the handles. `builtin`: the robot's own
    behaviour, which takes no "audio" lease (it keeps silent while one is held)."""

    def __init__(self, node: Node, leases: LeaseTable, timeout: float,
                 limit: ActionLimit | None = None, builtin: bool = False) -> None:
        super().__init__(node, leases, timeout, limit)
        self.builtin = builtin
        self._statuses: Watchers[GoalStatus] = Watchers("speaker status")
        self._frees: Watchers[bool] = Watchers("speaker free")
        self._free: Subscription | None = None
        self._handles: BoundedDict[str, SoundHandle] = BoundedDict(256)
        self._early: BoundedDict[str, m.PlaySoundStatus] = BoundedDict(64)
        """Statuses that came before their goal's reply (the action publishes
        ACCEPTED, even the end of a short sound, before the reply is read)."""
        self._status = node.subscribe(keys.PLAY_SOUND_STATUS, self._on_status, delivery="queue")

    def _on_status(self, status: m.PlaySoundStatus, _key: str) -> None:
        with self._lock:
            handle = self._handles.get(status.goal_id)
            if handle is None:
                self._early[status.goal_id] = status
        if handle is not None:
            handle.update(status)
        self._statuses.notify(GoalStatus(status.goal_id, status.state, status.message,
                                         status.stamp_ns))

    def on_status(self, callback: Callable[[GoalStatus], Any]) -> Watch:
        """Call `callback(status)` for every goal's status, anyone's (the robot's
        behaviour follows the speaker as a whole), until the returned watch or
        the bot closes; first with the newest status known, if any (the latched
        one of a goal that may have ended before this program started)."""
        return self._statuses.add(callback)

    def on_free(self, callback: Callable[[bool], Any]) -> Watch:
        """Call `callback(free)` whenever the player says whether it is idle
        (`audio/device_free`, latched: the current value first), until the
        returned watch or the bot closes."""
        with self._lock:
            if self._free is None:
                self._free = self.node.subscribe(
                    keys.DEVICE_FREE, lambda msg, _key: self._frees.notify(msg.data),
                    delivery="queue")
        return self._frees.add(callback)

    def play(self, sound: Sound, timeout: float | None = None) -> SoundHandle:
        """Start a sound of `[audio.sounds]`, `say:<text>` or a file (`goal_sound`
        tells which); Refused with the action's reason, the player's for a file
        it may not play, or the controller's when the speaker is held."""
        goal = goal_sound(sound)
        self._take("play")
        limit = self.timeout if timeout is None else timeout
        handle = self._start(goal, limit)
        if m.sound_file(goal) is not None:
            self._judged(handle, limit)
        return handle

    @staticmethod
    def _judged(handle: SoundHandle, limit: float) -> None:
        """Wait for the player's verdict on a file goal: Refused with its reason
        when the goal ended ABORTED (the sandbox's refusal, a bad file)."""
        try:
            state = handle.started(limit)
        except TimedOut:
            with contextlib.suppress(Exception):
                handle.cancel(limit)
            raise
        if state == "ABORTED":
            raise Refused(handle.message)

    def _start(self, sound: str, limit: float) -> SoundHandle:
        lease = self._audio_lease(limit)
        try:
            reply: m.PlaySoundReply = call(
                self.node, keys.PLAY_SOUND, m.PlaySound(sound=sound), limit,
                hint="is the audio service running? `buddybot run audio`")
        except BaseException:
            if lease is not None:
                release_quietly(lease)
            raise
        if not reply.accepted:
            if lease is not None:
                release_quietly(lease)
            raise Refused(reply.message)
        handle = SoundHandle(self, reply.goal_id, sound, lease)
        with self._lock:
            self._handles[reply.goal_id] = handle
            early = self._early.pop(reply.goal_id, None)
        if early is not None:
            handle.update(early)
        return handle

    def say(self, text: str, timeout: float | None = None) -> SoundHandle:
        """Speak any `text` (1..TTS_MAX_CHARS printable characters, surrounding
        spaces dropped); ValueError saying what is wrong with it."""
        if not isinstance(text, str):
            raise ValueError(f"say() speaks a str, not {text!r}")
        sound = m.TTS_PREFIX + text
        m.spoken_text(sound)
        self._take("say")
        return self._start(sound, self.timeout if timeout is None else timeout)

    def _audio_lease(self, timeout: float) -> Lease | None:
        """An "audio" lease for one sound, or None: the program holds one already,
        or no eyes driver answers (nobody to share the speaker with)."""
        if self.builtin or self.leases.holding("audio") is not None:
            return None
        try:
            return self.leases.acquire(["audio"], "app", None, timeout, counted=False)
        except NoService as exc:
            log.debug("playing without an audio lease: %s", exc)
            return None

    def cancel(self, goal_id: str, timeout: float) -> bool:
        """Ask the player to stop goal `goal_id`; whether it did (False: no such
        goal playing). NoService when nobody answers."""
        reply: m.TriggerReply = call(self.node, keys.PLAY_SOUND_CANCEL,
                                     m.CancelGoal(goal_id=goal_id), timeout,
                                     hint="is the audio service running?")
        return reply.success

    def close(self) -> None:
        self._statuses.clear()
        self._frees.clear()
        if self._free is not None:
            self._free.close()
        self._status.close()


def release_quietly(lease: Lease) -> None:
    """Release a lease taken for one action; a failure only leaves it to end with
    the program's token (logged)."""
    try:
        lease.release()
    except Exception as exc:
        log.warning("could not release lease %s: %s", lease.lease_id, exc)
