"""Render every expression in every eye style and make a labelled contact sheet.

Starts a router and one `buddybot run eye-renderer --no-browser --style S`
per style (as in production), opens the page in Debian's headless Chromium
through Playwright, feeds each expression with the lids the eyes driver
would send for it (driver.lids_for_expression), waits until the pose has
arrived and saves a screenshot; then tiles them, one row per style, one
column per expression, with labels.

    .venv/bin/python scripts/eyes_contact_sheet.py [--out docs/images/eyes-contact-sheet.png]
        [--shots DIR] [--size 400x240] [--styles glow,eyeball] [--style-file FILE]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from buddybot.contract import messages as m
from buddybot.eyes import driver, styles
from buddybot.tools.testing import Router, free_port, run_service, wait_port

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]
LABEL_H = 30


def feed_expression(page: Any, action: m.ExpressionAction) -> None:
    """What the renderer would forward for `action`: the driver's lids, then the
    expression itself; returns once the pose and the lids have arrived."""
    for lids in driver.lids_for_expression(m.ScreenExpression(stamp_ns=1, action=action)):
        msg = {"eye_id": int(lids.eye_id), "top_lid_position": lids.top_lid_position,
               "bottom_lid_position": lids.bottom_lid_position}
        page.evaluate("(t) => window.eyes.receive(t)", json.dumps({"topic": "lids", "msg": msg}))
    page.evaluate("(t) => window.eyes.receive(t)",
                  json.dumps({"topic": "expression", "msg": {"action": int(action)}}))
    wait_still(page)


def wait_still(page: Any) -> None:
    """Until the pose change is over and the lids and gaze are at their targets."""
    page.wait_for_function(
        """() => {
          const e = window.eyes, c = e.cur, t = e.target, near = (a, b) => Math.abs(a - b) < 0.05;
          return c.poseT >= 1 && near(c.yaw, t.yaw) && near(c.pitch, t.pitch)
            && ["left", "right"].every(s => near(c.lids[s].top, t.lids[s].top)
                                        && near(c.lids[s].bottom, t.lids[s].bottom));
        }""", timeout=15_000)


def open_page(browser: Any, port: int, width: int, height: int) -> Any:
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(f"http://127.0.0.1:{port}/eyes?eye=both&blink=0&saccade=0")
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002",
                           timeout=30_000)
    return page


def shoot_style(browser: Any, port: int, width: int, height: int) -> dict[str, bytes]:
    """Screenshots (PNG) of every expression, by name, from the renderer on `port`."""
    page = open_page(browser, port, width, height)
    shots = {}
    for action, name in zip(m.ExpressionAction, styles.EXPRESSIONS, strict=True):
        feed_expression(page, action)
        if name == "SLEEP":   # the breathing glow: shown at its brightest
            page.wait_for_timeout(50)
        shots[name] = page.screenshot()
    page.close()
    return shots


def sheet(rows: dict[str, dict[str, bytes]]) -> np.ndarray:
    """One row per style, one labelled tile per expression."""
    out = []
    for style, shots in rows.items():
        tiles = []
        for name, png in shots.items():
            img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
            label = np.full((LABEL_H, img.shape[1], 3), 24, np.uint8)
            cv2.putText(label, f"{style}: {name}", (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                        (235, 235, 235), 1, cv2.LINE_AA)
            tile = np.vstack([img, label])
            tiles.append(cv2.copyMakeBorder(tile, 2, 2, 2, 2, cv2.BORDER_CONSTANT,
                                            value=(60, 60, 60)))
        out.append(np.hstack(tiles))
    return np.vstack(out)


def render(style_names: list[str], width: int, height: int,
           style_file: str | None = None) -> dict[str, dict[str, bytes]]:
    """Every expression of every style in `style_names`, through real processes."""
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium not installed (scripts/chromium.sh installs it)")
    from playwright.sync_api import sync_playwright

    router = Router()
    procs = []
    rows: dict[str, dict[str, bytes]] = {}
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
                for name, port in ports.items():
                    rows[name] = shoot_style(browser, port, width, height)
            finally:
                browser.close()
    finally:
        for proc in procs:
            proc.stop()
        router.stop()
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/images/eyes-contact-sheet.png")
    parser.add_argument("--shots", default="", help="also save every screenshot here")
    parser.add_argument("--size", default="400x240", help="page size of each tile")
    parser.add_argument("--styles", default="glow,eyeball", help="comma-separated styles")
    parser.add_argument("--style-file", default=None, help="a style file to load as well")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    rows = render(args.styles.split(","), width, height, args.style_file)
    if args.shots:
        folder = Path(args.shots)
        folder.mkdir(parents=True, exist_ok=True)
        for style, shots in rows.items():
            for name, png in shots.items():
                (folder / f"{style}_{name}.png").write_bytes(png)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), sheet(rows), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
