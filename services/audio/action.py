"""`buddybot run audio`: the `audio/play_sound` action server.

Thin adapter around `GoalBook`: a goal (`PlaySound{sound}`) is checked
against `[audio.sounds]` and the player's liveliness, answered at once
with `{goal_id, accepted, message}`, then handed to the player by name
(`audio/play_file`) on a worker thread. Status goes out on the latched
`audio/play_sound/status`: ACCEPTED, PLAYING with progress every
`progress_period_s`, then SUCCEEDED when `audio/device_free` turns true,
CANCELED (cancel query, preemption) or ABORTED (with the player's reason).

"Is the player running" has one source of truth: the set of its live
instances (`Node.watch_node`, liveliness tokens). It does not depend on the
order in which a token and a `device_free` sample arrive, which differs
after a router restart. The instance that answered a play request is
remembered, so when that process dies the goal is aborted even while
another token of the same name (a second instance, or a fake one) lives.
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Callable

from buddybot.audio import protocol
from buddybot.audio.goals import GoalBook
from buddybot.audio.settings import AudioSettings
from buddybot.audio.sounds import effective_sounds
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import limits
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import CallError, Node, NoReplyError, new_goal_id
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext

RETRY_S = 0.05
"""Pause between play requests that found no player queryable yet (a starting
player declares its token before its queryables)."""
TEXT_MAX = 1000
"""Characters of a player's message kept in a status or a log line (they name
files, whose paths may be long, but never a client's whole request)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every option overrides an `[audio]` key (defaults and ranges: settings.py)."""
    settings_option(parser, "--busy-policy", struct=AudioSettings, field="busy_policy")
    settings_option(parser, "--player", struct=AudioSettings, field="player", metavar="NODE")


def settings_from(ctx: ServiceContext) -> AudioSettings:
    """`[audio]` with the command line on top: what `run` serves with (`--player ""`
    is refused by `merge`, not ignored as it once was)."""
    return merge(ctx.config.section(AudioSettings), ctx.args)


class ActionServer:
    """Wires a GoalBook to the node: requests, cancels, player state, progress.

    Every goal is answered by `_on_goal` at once (accepted or refused with
    the reason); the one worker thread only ever holds the newest accepted
    goal (a preempted goal was already ended in the book), so a burst of
    goals cannot queue up work.
    """

    def __init__(self, node: Node, settings: AudioSettings, policy: str) -> None:
        self.node = node
        self.settings = settings
        sounds = effective_sounds(settings.sounds, AudioSettings().sounds)
        self.book = GoalBook(sounds.keys(), policy)
        self.lock = threading.Lock()
        self.status = node.publisher(keys.PLAY_SOUND_STATUS)
        self.instances: frozenset[str] = frozenset()
        """Live instances (Zenoh ids) of the player node: running = not empty."""
        self.answering: str | None = None
        """The player instance that accepted the active goal's play request."""
        self.device_free: bool | None = None
        self._wake = threading.Condition()
        self._pending: tuple[str, str] | None = None
        """The newest accepted goal (id, sound) not yet handed to the player."""
        self._players_changed = False
        self._closed = False

    def apply_settings(self, settings: AudioSettings) -> None:
        """A live parameter change: the busy policy decides the next goal, the
        player timeout the next call. Sounds, the player's name and the progress
        period are read at start (restart-only)."""
        with self.lock:
            self.settings = settings
            self.book.policy = settings.busy_policy

    def start(self) -> None:
        node = self.node
        self._report_players(frozenset())
        node.subscribe(keys.DEVICE_FREE, self._on_device_free, delivery="queue")
        node.watch_node(self.settings.player, self._on_players)
        node.serve(keys.PLAY_SOUND, self._on_goal)
        node.serve(keys.PLAY_SOUND_CANCEL, self._on_cancel)
        node.every(self.settings.progress_period_s, self._tick, name="progress")
        threading.Thread(target=self._work_loop, name="goals", daemon=True).start()

    def close(self) -> None:
        with self._wake:
            self._closed = True
            self._wake.notify()

    def _publish(self, statuses: list[m.PlaySoundStatus]) -> None:
        for status in statuses:
            self.status.put(status)
            if status.state in m.TERMINAL_GOAL_STATES:
                self.node.log.info("goal %s %s %s", status.goal_id, status.state,
                                   limits.clip(status.message, TEXT_MAX))

    # -- inputs --

    def _on_players(self, instances: frozenset[str]) -> None:
        """The player's live instances changed (Zenoh's thread: note it, hand over)."""
        with self.lock:
            self.instances = instances
        with self._wake:
            self._players_changed = True
            self._wake.notify()

    def _on_device_free(self, msg: m.Bool, _key: str) -> None:
        with self.lock:
            self.device_free = msg.data
            if msg.data:
                self._publish(self.book.device_free(time.monotonic(), msg.stamp_ns))

    def _on_goal(self, req: m.PlaySound) -> m.PlaySoundReply:
        goal_id = new_goal_id()
        with self.lock:
            busy = self.device_free is False
            decision = self.book.request(goal_id, req.sound, player_present=bool(self.instances),
                                         player_busy=busy)
            self._publish(decision.statuses)
            self.node.diagnostics.values["goals_tracked"] = self.book.tracked
        if decision.accepted:
            with self._wake:
                self._pending = (goal_id, req.sound)  # replaces a goal it preempted
                self._wake.notify()
        else:
            self.node.diagnostics.increment("refused")
            self.node.log.info("refused goal for %r: %s", limits.clip(req.sound),
                               decision.reply.message)
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
                reply = m.TriggerReply(success=True, message=limits.clip(
                    f"canceled, but the player did not stop: {exc}", TEXT_MAX))
        self._publish(result.statuses)
        return reply

    def _tick(self) -> None:
        with self.lock:
            self._publish(self.book.tick(time.monotonic(), self.device_free))

    # -- the worker: player changes and handing goals to the player --

    def _work_loop(self) -> None:
        while True:
            with self._wake:
                while not (self._closed or self._pending or self._players_changed):
                    self._wake.wait()
                if self._closed:
                    return
                pending, self._pending = self._pending, None
                changed, self._players_changed = self._players_changed, False
            if changed:
                self._check_players()
            if pending is None:
                continue
            try:
                self._play(*pending)
            except Exception as exc:
                self.node.log.exception("goal %s failed", pending[0])
                with self.lock:
                    self._publish(self.book.failed(pending[0], f"internal error: {exc!r}"))

    def _check_players(self) -> None:
        """Abort the active goal when the player, or the instance playing it, is gone."""
        with self.lock:
            instances = self.instances
            if not instances:
                self._publish(self.book.player_lost())
                self.answering = None
            elif self.answering is not None and self.answering not in instances:
                self._publish(self.book.player_lost(
                    f"the audio player that was playing it ({self.answering}) stopped running"))
                self.answering = None
        self._report_players(instances)

    def _report_players(self, instances: frozenset[str]) -> None:
        diag = self.node.diagnostics
        player = self.settings.player
        diag.values["player_instances"] = len(instances)
        if diag.message.startswith(f"another {self.node.name} is running"):
            return  # the runtime's own duplicate warning matters more; it clears it
        if not instances:
            diag.set("WARN", f"audio player {player} not running")
        elif len(instances) > 1:
            diag.set("WARN", f"{len(instances)} instances of {player}: "
                     f"{limits.clip(', '.join(sorted(instances)))}")
        else:
            diag.set("OK", "running")

    def _play(self, goal_id: str, sound: str) -> None:
        def still_wanted() -> bool:
            with self.lock:
                return self.book.should_play(goal_id) and bool(self.instances)

        if not still_wanted():
            return
        with self.lock:
            self.answering = None
        asked_at, asked_ns = time.monotonic(), m.now_ns()
        try:
            reply, replier = self._ask_player(m.PlayAudioFile(path=sound), still_wanted)
        except ServiceError as exc:
            with self.lock:
                self._publish(self.book.failed(
                    goal_id, limits.clip(f"audio player: {exc}", TEXT_MAX)))
            return
        lost = False
        with self.lock:
            if not reply.success:
                self._publish(self.book.failed(goal_id, limits.clip(reply.message, TEXT_MAX)))
                return
            statuses = self.book.started(goal_id, protocol.parse_duration(reply.message),
                                         asked_at, asked_ns)
            if statuses:
                self.answering = replier
                lost = replier is not None and replier not in self.instances
            self._publish(statuses)
            orphan = not statuses and self.book.active is None
        if lost:  # it died between answering and now
            with self._wake:
                self._players_changed = True
                self._wake.notify()
        if orphan:  # canceled while the player was starting it
            try:
                self.node.call(keys.AUDIO_STOP, m.Trigger(),
                               timeout=self.settings.player_timeout_s)
            except ServiceError as exc:
                self.node.log.warning("could not stop a canceled goal's sound: %s",
                                      limits.clip(exc, TEXT_MAX))

    def _ask_player(self, request: m.PlayAudioFile, still_wanted: Callable[[], bool]
                    ) -> tuple[m.TriggerReply, str | None]:
        """The player's reply to a play request and the instance that sent it.

        No reply at all while the player's token is up means its queryables
        are not declared yet (it is starting, or reconnecting after a router
        restart): asked again until `player_timeout_s` is spent.
        """
        timeout = self.settings.player_timeout_s
        deadline = time.monotonic() + timeout
        while True:
            left = max(0.01, deadline - time.monotonic())
            try:
                # with_replier: the instance (zid) whose queryable answered
                answer = self.node.call(keys.PLAY_FILE, request, timeout=left,
                                        with_replier=True)
                return answer.value, answer.replier
            except NoReplyError:
                pass
            except CallError as exc:  # the goal's message names the player already
                raise ServiceError(exc.reason) from None
            if time.monotonic() + RETRY_S >= deadline or not still_wanted():
                raise ServiceError(f"no reply within {timeout:g} s (is it running?)")
            time.sleep(RETRY_S)


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    policy = settings.busy_policy
    node = ctx.node()
    server = ActionServer(node, settings, policy)
    try:
        LiveSettings(settings, server.apply_settings).serve(node)
        server.start()
        node.log.info("play_sound action ready (sounds: %s; busy policy %s)",
                      ", ".join(sorted(server.book.sounds)), policy)
        node.spin()
    finally:
        server.close()
        node.close()
    return 0
