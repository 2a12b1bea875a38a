"""Render the eyes with Chromium: every expression in every style at small-screen sizes,
and strips of frames taken during the blends between expressions.

Starts a router and one `buddybot run eye-renderer --no-browser --style S` per style
(as in production) and opens the page in Debian's headless Chromium through
Playwright, with Playwright's clock driving the page's time: every frame is taken at
an exact moment of an animation, whatever the machine's load. Each expression is fed
with the lids the eyes driver would send for it (driver.lids_for_expression).

Writes, into --out-dir (docs/images):
  eyes-contact-sheet.png        every expression, both styles, 320x240, both eyes
  eyes-contact-sheet-round.png  the same, one eye per 240x240 round screen
  eyes-blend-NAME.png           frames during a blend (AWAKE->GRIN, falling asleep,
                                LOVE and back, a person coming near, a sleeping breath)

    .venv/bin/python scripts/eyes_contact_sheet.py [--out-dir docs/images] [--shots DIR]
        [--styles glow,eyeball] [--style-file FILE] [--only sheets|blends]
"""

from __future__ import annotations

import argparse
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from buddybot.contract import messages as m
from buddybot.eyes import driver, styles, wire
from buddybot.eyes.settings import EyesSettings
from buddybot.tools.testing import Router, free_port, paused_eye_page, run_service, wait_port

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]
LABEL_H = 22
A = m.ExpressionAction
FRAME_MS = 16
"""One step of the page's clock: about one 60 Hz display frame."""
BREATH_MS = 4000
"""One slow breath (draw.js BREATH_HZ)."""


@dataclass(frozen=True)
class Screen:
    """A real small display: its pixels, which eyes its page shows and whether it is round."""

    name: str
    width: int
    height: int
    eye: str
    round: bool


SCREENS = (
    Screen("", 320, 240, "both", False),       # a 2.8" ILI9341 TFT: both eyes on one screen
    Screen("-round", 240, 240, "left", True),  # a 1.28" GC9A01 round TFT per eye
)
STRIP = SCREENS[1]
"""Blend strips show one eye, on the round screen."""


@dataclass(frozen=True)
class Step:
    """Something sent to the page, then `frames` frames over the blend it starts
    (`ms`: how long to take frames; 0: the pose's transition time)."""

    action: A | None = None
    distance_cm: float | None = None
    frames: int = 5
    ms: float = 0.0


BLENDS: dict[str, tuple[A, list[Step]]] = {
    "awake-grin": (A.EYE_AWAKE, [Step(A.EYE_GRIN)]),
    "falling-asleep": (A.EYE_AWAKE, [Step(A.EYE_SLEEPY, frames=4), Step(A.EYE_SLEEP, frames=5)]),
    "awake-love": (A.EYE_AWAKE, [Step(A.ANIMATE_LOVE)]),
    "love-awake": (A.ANIMATE_LOVE, [Step(A.EYE_AWAKE)]),
    "pupil-near": (A.EYE_AWAKE, [Step(distance_cm=30, frames=5, ms=800)]),
    "asleep-breath": (A.EYE_SLEEP, [Step(frames=5, ms=BREATH_MS / 2)]),
}
"""Name -> (the expression it starts from, the steps). pupil-near starts with a person
at 300 cm; asleep-breath sends nothing and shows half a breath (out, then in)."""


def send(page: Any, *msgs: m.Message) -> None:
    """Messages into the page as the renderer forwards them."""
    for msg in msgs:
        page.evaluate("(t) => window.eyes.receive(t)",
                      wire.encode(wire.TOPIC_NAMES[type(msg)], msg))


def feed_expression(page: Any, action: A) -> None:
    """What the renderer forwards for `action`: the driver's lids, then the expression."""
    expression = m.ScreenExpression(stamp_ns=1, action=action)
    send(page, *driver.lids_for_expression(expression), expression)


def feed_distance(page: Any, cm: float) -> None:
    """What the eyes driver makes of a person straight ahead at `cm`: the direction
    with the distance and the pupil's dilation from the default curve."""
    control = m.EyeControl(stamp_ns=1, yaw=0.0, pitch=0.0, target_distance_cm=cm)
    curve = driver.PupilCurve.from_points(EyesSettings().pupil_curve)
    send(page, driver.direction_from_control(control),
         driver.pupil_from_control(control, curve, EyesSettings().unknown_distance_percent))


def settle(page: Any, ms: float = 2500) -> None:
    """Run the page's clock until every blend is over, then to the top of a breath
    (the brightest moment of a sleeping glow)."""
    page.clock.run_for(int(ms))
    phase = page.evaluate("window.eyes.serverTime()") % BREATH_MS
    page.clock.run_for(int(BREATH_MS - phase) % BREATH_MS)


def shoot_style(browser: Any, port: int, screen: Screen) -> dict[str, bytes]:
    """Screenshots (PNG) of every expression, by name, from the renderer on `port`."""
    page = paused_eye_page(browser, port, screen.width, screen.height, screen.eye)
    shots = {}
    for action, name in zip(A, styles.EXPRESSIONS, strict=True):
        feed_expression(page, action)
        settle(page)
        shots[name] = page.screenshot()
    page.close()
    return shots


def blend_ms(style: styles.Style, action: A) -> float:
    pose = style.poses[styles.EXPRESSIONS[int(action)]]
    return pose.transition_ms or style.transition_ms


def shoot_blend(browser: Any, port: int, style: styles.Style, start: A,
                steps: list[Step]) -> list[tuple[str, bytes]]:
    """(label, PNG) of each frame of a blend: the first as a step is sent, the others
    evenly over it (a step after another one starts where that one's last frame is)."""
    page = paused_eye_page(browser, port, STRIP.width, STRIP.height, STRIP.eye)
    feed_expression(page, start)
    if any(step.distance_cm is not None for step in steps):
        feed_distance(page, 300)
    settle(page)
    frames = []
    elapsed = 0.0
    for step in steps:
        if step.action is not None:
            feed_expression(page, step.action)
        if step.distance_cm is not None:
            feed_distance(page, step.distance_cm)
        ms = step.ms or blend_ms(style, step.action or start)
        what = styles.EXPRESSIONS[int(step.action)] if step.action is not None else (
            f"{step.distance_cm:.0f} cm" if step.distance_cm is not None else "")
        page.clock.run_for(FRAME_MS)    # the frame that starts the blend
        taken = 0.0
        sent = f" {what} sent" if what else ""
        if frames:                      # that moment is the last frame of the step before
            frames[-1] = (frames[-1][0] + sent, frames[-1][1])
        for i in range(0 if not frames else 1, step.frames):
            at = ms * i / (step.frames - 1)
            page.clock.run_for(max(0, round(at - taken)))
            taken = at
            frames.append((f"+{elapsed + at:.0f} ms" + (sent if i == 0 else ""),
                           page.screenshot()))
        elapsed += ms
    page.close()
    return frames


def tile(png: bytes, label: str, round_screen: bool) -> np.ndarray:
    """A screenshot with its label under it (a round screen: what lies outside it greyed)."""
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if round_screen:
        h, w = img.shape[:2]
        outside = np.ones((h, w), np.uint8)
        cv2.circle(outside, (w // 2, h // 2), min(w, h) // 2, 0, -1, cv2.LINE_AA)
        img[outside > 0] = (img[outside > 0] * 0.25 + 40).astype(np.uint8)
    bar = np.full((LABEL_H, img.shape[1], 3), 24, np.uint8)
    cv2.putText(bar, label, (6, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (235, 235, 235), 1,
                cv2.LINE_AA)
    return cv2.copyMakeBorder(np.vstack([img, bar]), 2, 2, 2, 2, cv2.BORDER_CONSTANT,
                              value=(60, 60, 60))


def grid(tiles: list[np.ndarray], columns: int) -> np.ndarray:
    rows = []
    for i in range(0, len(tiles), columns):
        row = tiles[i:i + columns]
        row += [np.zeros_like(tiles[0])] * (columns - len(row))
        rows.append(np.hstack(row))
    return np.vstack(rows)


def write_png(path: Path, img: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {path} ({path.stat().st_size // 1024} kB)")


def render(style_names: list[str], style_file: str | None, out_dir: Path,
           shots_dir: Path | None, only: str) -> None:
    """Every sheet and strip, through real processes."""
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium not installed (scripts/chromium.sh installs it)")
    from playwright.sync_api import sync_playwright

    library = styles.load(Path(style_file) if style_file else None)
    router = Router()
    procs = []
    try:
        ports = {}
        for i, name in enumerate(style_names):
            port = free_port()
            extra = ["--style-file", style_file] if style_file else []
            # One robot name each: two renderers of one robot would be a duplicate node.
            procs.append(run_service("eye-renderer", router.endpoint, "--port", str(port),
                                     "--no-browser", "--style", name, *extra,
                                     robot=f"sheet{i}"))
            ports[name] = port
        for port in ports.values():
            wait_port(port, 30)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            try:
                if only in ("", "sheets"):
                    for screen in SCREENS:
                        tiles = []
                        for name, port in ports.items():
                            for expr, png in shoot_style(browser, port, screen).items():
                                tiles.append(tile(png, f"{name}: {expr}", screen.round))
                                if shots_dir:
                                    shots_dir.mkdir(parents=True, exist_ok=True)
                                    (shots_dir / f"{name}_{expr}{screen.name}.png").write_bytes(
                                        png)
                        write_png(out_dir / f"eyes-contact-sheet{screen.name}.png",
                                  grid(tiles, 3))
                if only in ("", "blends"):
                    for blend, (start, steps) in BLENDS.items():
                        rows = []
                        for name, port in ports.items():
                            frames = shoot_blend(browser, port, library.get(name), start, steps)
                            rows.append(np.hstack([tile(png, f"{name}: {label}", True)
                                                   for label, png in frames]))
                        write_png(out_dir / f"eyes-blend-{blend}.png", np.vstack(rows))
            finally:
                browser.close()
    finally:
        for proc in procs:
            proc.stop()
        router.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", default="docs/images")
    parser.add_argument("--shots", default="", help="also save every still here")
    parser.add_argument("--styles", default="glow,eyeball", help="comma-separated styles")
    parser.add_argument("--style-file", default=None, help="a style file to load as well")
    parser.add_argument("--only", default="", choices=["", "sheets", "blends"])
    args = parser.parse_args()
    render(args.styles.split(","), args.style_file, Path(args.out_dir),
           Path(args.shots) if args.shots else None, args.only)
    return 0


if __name__ == "__main__":
    sys.exit(main())
