"""`buddybot run audio`: the seed's audio_hld, the `audio/play_sound` action server.

Thin adapter around `GoalBook`: a goal (`PlaySound{sound}`) is checked
against `[audio.sounds]` and the player's liveliness, answered at once
with `{goal_id, accepted, message}`, then handed to the player by name
(`audio/play_file`) on a worker thread. Status goes out on the latched
`audio/play_sound/status`: ACCEPTED, PLAYING with progress every
`progress_period_s`, then SUCCEEDED when `audio/device_free` turns true,
CANCELED (cancel query, preemption) or ABORTED (with the player's reason).
"""

from __future__ import annotations

import argparse
import queue
import threading
import time
from typing import Any

import msgspec
import zenoh

from buddybot.audio import protocol
from buddybot.audio.goals import GoalBook
from buddybot.audio.settings import AudioSettings
from buddybot.audio.sounds import effective_sounds
from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node, ServiceError, new_goal_id
from buddybot.core.service import ServiceContext


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--busy-policy", choices=["preempt", "refuse"],
                        help="what a goal does while another plays (default from config, "
                        "else preempt)")
    parser.add_argument("--player", metavar="NODE",
                        help="node name of the audio player (default audio-player)")


class ActionServer:
    """Wires a GoalBook to the node: requests, cancels, player state, progress."""

    def __init__(self, node: Node, settings: AudioSettings, policy: str) -> None:
        self.node = node
        self.settings = settings
        sounds = effective_sounds(settings.sounds, AudioSettings().sounds)
        self.book = GoalBook(sounds.keys(), policy)
        self.lock = threading.Lock()
        self.status = node.publisher(keys.PLAY_SOUND_STATUS)
        self.player_alive = False
        """The player's liveliness token is there and it published device_free since
        (its token comes before its queryables; device_free comes after them)."""
        self._token = False
        self.device_free: bool | None = None
        self._goals: queue.SimpleQueue[tuple[str, str] | None] = queue.SimpleQueue()
        """Work for the goal thread: (goal id, sound) to play, ("", "") = player lost."""
        self._liveliness: Any = None

    def start(self) -> None:
        node = self.node
        node.subscribe(keys.DEVICE_FREE, self._on_device_free, delivery="queue")
        player_key = node.key(keys.NODES, node=self.settings.player)
        self._liveliness = node.session.liveliness().declare_subscriber(
            player_key, self._on_player, history=True)
        node.serve(keys.PLAY_SOUND, self._on_goal)
        node.serve(keys.PLAY_SOUND_CANCEL, self._on_cancel)
        node.every(self.settings.progress_period_s, self._tick, name="progress")
        threading.Thread(target=self._play_loop, name="goals", daemon=True).start()

    def close(self) -> None:
        self._goals.put(None)
        if self._liveliness is not None:
            self._liveliness.undeclare()

    def _publish(self, statuses: list[m.PlaySoundStatus]) -> None:
        for status in statuses:
            self.status.put(status)
            if status.state in m.TERMINAL_GOAL_STATES:
                self.node.log.info("goal %s %s %s", status.goal_id, status.state,
                                   status.message)

    # -- inputs --

    def _on_player(self, sample: zenoh.Sample) -> None:
        """Liveliness of the player (Zenoh's thread: only set a flag and hand over)."""
        alive = sample.kind == zenoh.SampleKind.PUT
        with self.lock:
            self._token = alive
            if not alive:
                self.player_alive = False
        if not alive:
            self._goals.put(("", ""))

    def _on_device_free(self, msg: m.Bool, _key: str) -> None:
        with self.lock:
            self.device_free = msg.data
            self.player_alive = self._token
            if msg.data:
                self._publish(self.book.device_free(time.monotonic()))

    def _on_goal(self, req: m.PlaySound) -> m.PlaySoundReply:
        goal_id = new_goal_id()
        with self.lock:
            busy = self.device_free is False
            decision = self.book.request(goal_id, req.sound, player_present=self.player_alive,
                                         player_busy=busy)
            self._publish(decision.statuses)
        if decision.accepted:
            self._goals.put((goal_id, req.sound))
        else:
            self.node.diagnostics.increment("refused")
            self.node.log.info("refused goal for %r: %s", req.sound, decision.reply.message)
        return decision.reply

    def _on_cancel(self, req: m.CancelGoal) -> m.TriggerReply:
        with self.lock:
            result = self.book.cancel(req.goal_id)
        reply = result.reply
        if result.stop_player:
            try:
                self.node.call(keys.AUDIO_STOP, m.Trigger(),
                               timeout=self.settings.player_timeout_s)
            except ServiceError as exc:
                reply = m.TriggerReply(success=True,
                                       message=f"canceled, but the player did not stop: {exc}")
        self._publish(result.statuses)
        return reply

    def _tick(self) -> None:
        with self.lock:
            self._publish(self.book.tick(time.monotonic(), self.device_free))

    # -- the worker handing goals to the player --

    def _play_loop(self) -> None:
        while True:
            item = self._goals.get()
            if item is None:
                return
            if item == ("", ""):
                with self.lock:
                    self._publish(self.book.player_lost())
                self.node.diagnostics.set("WARN", "audio player not running")
                continue
            try:
                self._play(*item)
            except Exception as exc:
                self.node.log.exception("goal %s failed", item[0])
                with self.lock:
                    self._publish(self.book.failed(item[0], f"internal error: {exc!r}"))

    def _play(self, goal_id: str, sound: str) -> None:
        with self.lock:
            if not self.book.should_play(goal_id):
                return
        self.node.diagnostics.set("OK", "running")
        try:
            reply = self.node.call(keys.PLAY_FILE, m.PlayAudioFile(path=sound),
                                   timeout=self.settings.player_timeout_s)
        except ServiceError as exc:
            with self.lock:
                self._publish(self.book.failed(goal_id, f"audio player: {exc}"))
            return
        with self.lock:
            if not reply.success:
                self._publish(self.book.failed(goal_id, reply.message))
                return
            statuses = self.book.started(goal_id, protocol.parse_duration(reply.message),
                                         time.monotonic())
            self._publish(statuses)
            orphan = not statuses and self.book.active is None
        if orphan:  # canceled while the player was starting it
            try:
                self.node.call(keys.AUDIO_STOP, m.Trigger(),
                               timeout=self.settings.player_timeout_s)
            except ServiceError as exc:
                self.node.log.warning("could not stop a canceled goal's sound: %s", exc)


def run(ctx: ServiceContext) -> int:
    settings = ctx.config.audio
    if ctx.args.player:
        settings = msgspec.structs.replace(settings, player=ctx.args.player)
    policy = ctx.args.busy_policy or settings.busy_policy
    node = ctx.node()
    server = ActionServer(node, settings, policy)
    try:
        server.start()
        node.log.info("play_sound action ready (sounds: %s; busy policy %s)",
                      ", ".join(sorted(server.book.sounds)), policy)
        node.spin()
    finally:
        server.close()
        node.close()
    return 0
