"""The speaker: sounds played through the `audio/play_sound` action.

A goal names a sound of `[audio.sounds]` (docs/design.md 4.6); its reply
comes at once (accepted, or refused with the reason), its progress on the
latched `audio/play_sound/status`. `SoundHandle` follows one goal to its
final state. `say(text)` speaks a text the audio service has configured as
a `say:` sound: the action plays configured names only, so an arbitrary
text cannot be spoken through it.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Generator
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.contract.messages import TTS_PREFIX
from buddybot.runtime.limits import BoundedDict
from buddybot.runtime.node import Node
from buddybot.sdk.calls import call
from buddybot.sdk.errors import Refused, TimedOut
from buddybot.sdk.params import Params

WAIT_S = 120.0
"""How long `wait()` and `await handle` wait for a sound's end by default."""


def spoken_sound(sounds: dict[str, str], text: str) -> str | None:
    """The configured sound name that speaks `text` (surrounding spaces ignored)."""
    wanted = text.strip()
    for name, value in sorted(sounds.items()):
        if value.startswith(TTS_PREFIX) and value[len(TTS_PREFIX):].strip() == wanted:
            return name
    return None


class SoundHandle:
    """One sound being played: `state`, `wait()`, `cancel()`, `await handle`.

    `state` goes ACCEPTED -> PLAYING -> SUCCEEDED, CANCELED or ABORTED
    (`message` says why for the last two)."""

    def __init__(self, speaker: Speaker, goal_id: str, sound: str) -> None:
        self._speaker = speaker
        self.goal_id = goal_id
        self.sound = sound
        self.state: str = "ACCEPTED"
        self.message = ""
        self._ended = threading.Event()

    @property
    def done(self) -> bool:
        return self._ended.is_set()

    def update(self, status: m.PlaySoundStatus) -> None:
        if self._ended.is_set():
            return
        self.state, self.message = status.state, status.message
        if status.state in m.TERMINAL_GOAL_STATES:
            self._ended.set()

    def wait(self, timeout: float = WAIT_S) -> str:
        """The final state, once reached; TimedOut after `timeout` s."""
        if not self._ended.wait(timeout):
            raise TimedOut(f"sound {self.sound!r} (goal {self.goal_id}) still {self.state} "
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


class Speaker:
    """Goals to `audio/play_sound`, and their statuses routed to the handles."""

    def __init__(self, node: Node, params: Params, timeout: float) -> None:
        self.node = node
        self.params = params
        self.timeout = timeout
        self._lock = threading.Lock()
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

    def play(self, sound: str, timeout: float | None = None) -> SoundHandle:
        """Start a sound of `[audio.sounds]`; Refused with the action's reason."""
        limit = self.timeout if timeout is None else timeout
        reply: m.PlaySoundReply = call(
            self.node, keys.PLAY_SOUND, m.PlaySound(sound=sound), limit,
            hint="is the audio service running? `buddybot run audio`")
        if not reply.accepted:
            raise Refused(reply.message)
        handle = SoundHandle(self, reply.goal_id, sound)
        with self._lock:
            self._handles[reply.goal_id] = handle
            early = self._early.pop(reply.goal_id, None)
        if early is not None:
            handle.update(early)
        return handle

    def say(self, text: str, timeout: float | None = None) -> SoundHandle:
        """Speak `text`: the sound the audio service has configured as `say:<text>`."""
        sounds = self.params.get("audio", "sounds", timeout)
        name = spoken_sound(dict(sounds or {}), text)
        if name is None:
            raise Refused(f"the audio service speaks configured sounds only, and no "
                          f"[audio.sounds] entry is {TTS_PREFIX}{text.strip()} "
                          f"(add one, e.g. hello = \"{TTS_PREFIX}{text.strip()}\")")
        return self.play(name, timeout)

    def cancel(self, goal_id: str, timeout: float) -> None:
        call(self.node, keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id=goal_id), timeout,
             hint="is the audio service running?")

    def close(self) -> None:
        self._status.close()
