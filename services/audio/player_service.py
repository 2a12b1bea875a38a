"""`buddybot run audio-player`: the sound player as a Zenoh service.

Thin adapter around `Player`: queryables `audio/play_file`, `audio/stop`,
`audio/pause`, `audio/resume` answer `{success, message}`; the latched
`audio/device_free` is false while a sound plays (or is paused) and true
when it ended, was stopped or failed to start. A bad file or a missing
device is an unsuccessful reply naming the file and the reason, never an
exit. Only configured sounds and files in `[audio_player] sound_dirs` are
played; anything else is refused with one text (`access.py`).
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable
from typing import Any, BinaryIO

from buddybot.audio import protocol
from buddybot.audio.player import AudioError, Player
from buddybot.audio.settings import AudioPlayerSettings, AudioSettings
from buddybot.audio.sounds import effective_sounds
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import limits
from buddybot.runtime.config import config_dir
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext

TEXT_MAX = 1000
"""Characters of a refusal reason kept in a reply or a log line (enough for a
long file path, never a whole hostile request)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options overriding `[audio_player]` keys (defaults and ranges: settings.py), then
    `--tap`, which only exists on the command line."""
    struct = AudioPlayerSettings
    settings_option(parser, "--backend", struct=struct, field="backend")
    settings_option(parser, "--device", struct=struct, field="device", metavar="NAME")
    settings_option(parser, "--volume", struct=struct, field="volume", metavar="GAIN")
    settings_option(parser, "--sample-rate", struct=struct, field="sample_rate", metavar="HZ")
    parser.add_argument("--tap", metavar="FILE",
                        help="also write every sample handed to the device to FILE "
                        "(raw interleaved int16 little-endian, for tests)")


def settings_from(ctx: ServiceContext) -> AudioPlayerSettings:
    """`[audio_player]` with the command line on top, validated like the config file."""
    return merge(ctx.config.section(AudioPlayerSettings), ctx.args)


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    sounds = effective_sounds(ctx.config.audio.sounds, AudioSettings().sounds)
    tap_file = open(ctx.args.tap, "wb", buffering=0) if ctx.args.tap else None  # noqa: SIM115
    node = ctx.node()
    free = node.publisher(keys.DEVICE_FREE)
    diag = node.diagnostics

    def on_busy(busy: bool) -> None:
        free.put(m.Bool(stamp_ns=m.now_ns(), data=not busy))

    def on_started() -> None:
        stats = player.stats
        diag.values.update({
            "plays": stats.plays, "finished": stats.finished, "stops": stats.stops,
            "failures": stats.failures, "last_request_ns": stats.last_request_ns,
            "last_first_sample_ns": stats.last_first_sample_ns,
            "last_start_latency_ms": round(
                (stats.last_first_sample_ns - stats.last_request_ns) / 1e6, 3),
            "last_decode_ms": round(stats.last_decode_ms, 3),
        })
        diag.publish()

    player = Player(settings, sounds, config_dir(ctx.config), on_busy=on_busy,
                    on_started=on_started, tap=_writer(tap_file) if tap_file else None)
    try:
        opened = player.open()
        if opened is None:
            diag.set("ERROR", f"no audio device: {player.device_error}")
        elif opened.warning:
            diag.set("WARN", opened.warning)
        diag.values["backend"] = player.backend or "none"
        for problem in player.preload():
            node.log.warning("configured sound unusable: %s", problem)
            if opened is not None and not opened.warning:
                diag.set("WARN", problem)
        # Free before the queryables answer: a play request answered first turns
        # it false, and a "free" sent after that would end the sound's goal (the
        # action server retries a play request that finds no queryable yet).
        free.put(m.Bool(stamp_ns=m.now_ns(), data=True))
        _serve(node, player)
        LiveSettings(settings, player.apply_settings).serve(node)
        node.log.info("audio player ready (backend %s, %d Hz, %d channels)",
                      player.backend, settings.sample_rate, settings.channels)
        node.spin()
    finally:
        player.close()
        node.close()
        if tap_file is not None:
            with contextlib.suppress(OSError):
                tap_file.close()
    return 0


def _serve(node: Any, player: Player) -> None:
    def play(req: m.PlayAudioFile) -> m.TriggerReply:
        try:
            track = player.play(req.path)
        except AudioError as exc:
            # The text names a file (or repeats the request): clipped, so no
            # request can become a huge log line or reply.
            why = limits.clip(str(exc), TEXT_MAX)
            node.diagnostics.increment("failures")
            node.log.warning("cannot play: %s", why)
            return m.TriggerReply(success=False, message=why)
        return m.TriggerReply(success=True,
                              message=protocol.playing_message(track.name, track.duration_s))

    def stop(_req: m.Trigger) -> m.TriggerReply:
        was = player.stop()
        return m.TriggerReply(success=True, message="stopped" if was else "nothing was playing")

    def pause(_req: m.Trigger) -> m.TriggerReply:
        if player.pause():
            return m.TriggerReply(success=True, message="paused")
        return m.TriggerReply(success=False, message="nothing is playing")

    def resume(_req: m.Trigger) -> m.TriggerReply:
        if player.resume():
            return m.TriggerReply(success=True, message="resumed")
        return m.TriggerReply(success=False, message="nothing is paused")

    node.serve(keys.PLAY_FILE, play)
    node.serve(keys.AUDIO_STOP, stop)
    node.serve(keys.AUDIO_PAUSE, pause)
    node.serve(keys.AUDIO_RESUME, resume)


def _writer(file: BinaryIO) -> Callable[[bytes], None]:
    """The tap callback: every played chunk appended to the tap file."""

    def write(data: bytes) -> None:
        file.write(data)

    return write
