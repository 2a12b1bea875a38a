"""Which sensor model is on a line, recognised from its first report frames (pure).

The LD2410 starts its reports with `F4 F3 F2 F1` and a data type (0x01
engineering, 0x02 basic); the LD2450 with `AA FF 03 00`. Until one parser
has produced a report, every chunk goes to both; from then on only to the
winner, and the frames the winner had already parsed are handed out, so
nothing read while recognising is lost. An explicit model skips the
guessing. A sensor that changes model on the same line (another module
plugged into an ESP32's UART) stops producing frames for the chosen
parser: the reader's silence timeout reopens the line and recognises it
again.
"""

from __future__ import annotations

from buddybot.radar import ld2410, ld2450

LD2410 = "LD2410"
LD2450 = "LD2450"
AUTO = "auto"
MODELS = (LD2410, LD2450)
"""Models the bridge reads; `AUTO` (the default) recognises them."""

Frame = ld2410.Frame | ld2450.Frame


def describe(frame: Frame) -> str | None:
    """"LD2410 engineering", "LD2410 basic", "LD2450", or None (not a report)."""
    if isinstance(frame, ld2410.Report):
        return f"{LD2410} {'engineering' if frame.engineering else 'basic'}"
    if isinstance(frame, ld2450.Report):
        return LD2450
    return None


class Sniffer:
    """Feeds bytes to the parser(s) of the possible models; `model` once known."""

    def __init__(self, model: str = AUTO) -> None:
        if model not in (AUTO, *MODELS):
            raise ValueError(f"unknown radar model {model!r}; one of {(AUTO, *MODELS)}")
        self._ld2410 = ld2410.Parser()
        self._ld2450 = ld2450.Parser()
        self.model: str | None = None if model == AUTO else model
        self._held: dict[str, list[Frame]] = {LD2410: [], LD2450: []}

    @property
    def _active(self) -> ld2410.Parser | ld2450.Parser | None:
        if self.model is None:
            return None
        return self._ld2410 if self.model == LD2410 else self._ld2450

    def feed(self, chunk: bytes | bytearray) -> list[Frame]:
        """Frames of the recognised model (none while still recognising)."""
        active = self._active
        if active is not None:
            return list(active.feed(chunk))
        first = self._ld2410.feed(chunk)
        second = self._ld2450.feed(chunk)
        self._held[LD2410] += first
        self._held[LD2450] += second
        # Keep only a few frames (ACKs) while nothing has reported yet.
        for held in self._held.values():
            del held[:-16]
        for model, frames in ((LD2410, first), (LD2450, second)):
            if any(describe(f) for f in frames):
                self.model = model
                return self._held.pop(model)
        return []

    def reset(self) -> None:
        """Forget partial frames (the next bytes do not continue them)."""
        self._ld2410.reset()
        self._ld2450.reset()

    # Counters of the chosen parser; while recognising, what both agree on.
    def _counter(self, name: str, combine: str) -> int:
        active = self._active
        if active is not None:
            return int(getattr(active.stats, name))
        a, b = getattr(self._ld2410.stats, name), getattr(self._ld2450.stats, name)
        if combine == "sum":
            return int(a + b)
        return int(min(a, b) if combine == "min" else max(a, b))

    @property
    def intact_frames(self) -> int:
        return self._counter("intact_frames", "sum")

    @property
    def bad_frames(self) -> int:
        # A frame one parser rejects is bad (a command frame, which both parse, once).
        return self._counter("bad_frames", "max")

    @property
    def unusual_frames(self) -> int:
        return self._counter("unusual_frames", "sum")

    @property
    def skipped_bytes(self) -> int:
        """Bytes no parser could use (while recognising: skipped by both)."""
        return self._counter("skipped_bytes", "min")
