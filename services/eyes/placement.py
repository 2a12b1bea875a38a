"""Which eye goes on which display (docs/design.md section 4.5), pure: display lists in,
windows out.

The original ROS 2 design's rules, made exact:

* no display at all -> error;
* nothing configured: left eye on display 1, right eye on display 2;
  exactly one display -> both eyes in one window on it (the page draws
  the robot's left eye on the right half, as seen by a viewer);
* configured (eyes to show and/or a display per eye): more eyes than
  displays, or a display number that does not exist -> error; two eyes
  explicitly on the same display -> one window with both.

Displays are numbered from 1 in left-to-right, then top-to-bottom order
of their desktop position, so "display 1" is the leftmost screen whatever
order the OS lists them in.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

EyeName = Literal["left", "right"]
PageEye = Literal["left", "right", "both"]
EYES: tuple[EyeName, ...] = ("left", "right")


class PlacementError(Exception):
    """The configured placement cannot be realised; the message says why and what to do."""


@dataclass(frozen=True)
class Display:
    """A screen on the desktop (pixels, desktop coordinates)."""

    x: int
    y: int
    width: int
    height: int
    name: str = ""


@dataclass(frozen=True)
class Request:
    """What the user configured; None/empty = not configured (defaults apply)."""

    eyes: tuple[EyeName, ...] = ()
    left_display: int | None = None
    right_display: int | None = None

    @property
    def explicit(self) -> bool:
        return bool(self.eyes) or self.left_display is not None or self.right_display is not None


@dataclass(frozen=True)
class Window:
    """One kiosk window: the page's `eye` parameter and where it goes."""

    eye: PageEye
    display_number: int
    display: Display


def ordered(displays: Sequence[Display]) -> list[Display]:
    """Displays in numbering order (left to right, then top to bottom)."""
    return sorted(displays, key=lambda d: (d.x, d.y))


def describe(displays: Sequence[Display]) -> str:
    return ", ".join(
        f"{i}: {d.name or 'display'} {d.width}x{d.height}+{d.x}+{d.y}"
        for i, d in enumerate(ordered(displays), 1)
    ) or "none"


def plan(displays: Sequence[Display], request: Request = Request()) -> list[Window]:
    """The windows to open, or PlacementError with a message for the user."""
    screens = ordered(displays)
    n = len(screens)
    if n == 0:
        raise PlacementError(
            "no display found (no screen connected, or no DISPLAY/WAYLAND_DISPLAY): "
            "connect a screen, or run with --no-browser to only serve the eye pages"
        )
    if not request.explicit:
        if n == 1:
            return [Window("both", 1, screens[0])]
        return [Window("left", 1, screens[0]), Window("right", 2, screens[1])]

    wanted: tuple[EyeName, ...] = tuple(dict.fromkeys(request.eyes)) or EYES
    for eye in wanted:
        if eye not in EYES:
            raise PlacementError(f"unknown eye {eye!r}: use 'left' and/or 'right'")
    chosen: dict[EyeName, int] = {}
    if request.left_display is not None and "left" in wanted:
        chosen["left"] = request.left_display
    if request.right_display is not None and "right" in wanted:
        chosen["right"] = request.right_display
    explicit_same = len(chosen) == 2 and chosen["left"] == chosen["right"]
    if len(wanted) > n and not explicit_same:
        raise PlacementError(
            f"{len(wanted)} eyes configured ({', '.join(wanted)}) but only {n} display(s) "
            f"found ({describe(screens)}): configure fewer eyes, put both on one display "
            "with --left-display N --right-display N, or connect another screen"
        )
    # Unassigned eyes take the lowest display numbers not already taken.
    free = [i for i in range(1, n + 1) if i not in chosen.values()]
    for eye in wanted:
        if eye not in chosen:
            chosen[eye] = free.pop(0)
    for eye, number in chosen.items():
        if not 1 <= number <= n:
            raise PlacementError(
                f"{eye} eye configured on display {number} but only {n} display(s) "
                f"found ({describe(screens)})"
            )
    if explicit_same:
        number = chosen["left"]
        return [Window("both", number, screens[number - 1])]
    return [Window(eye, chosen[eye], screens[chosen[eye] - 1]) for eye in wanted]


def parse_geometry(text: str) -> Display:
    """`WIDTHxHEIGHT+X+Y` (X11 geometry) -> Display; ValueError when malformed."""
    try:
        size, x, y = text.strip().split("+")
        width, height = size.lower().split("x")
        display = Display(int(x), int(y), int(width), int(height), name=text.strip())
    except ValueError:
        raise ValueError(f"bad display geometry {text!r}: expected WIDTHxHEIGHT+X+Y") from None
    if display.width <= 0 or display.height <= 0:
        raise ValueError(f"bad display geometry {text!r}: size must be positive")
    return display
