"""Film the eyes through each scenario of the simulated world: one labelled frame strip each.

Runs `buddybot up --sim --scenario NAME` (the whole robot, private ports;
an angle radar for the scenarios that need bearings), opens its eye page in
Debian's headless Chromium through Playwright, waits for a lap to start and
takes a screenshot every `--every` seconds for one lap. Each tile is labelled
with the scenario time, who is really there (`sim/world`: distance and
bearing of each person, `face` when the camera can see it) and what the
robot's behaviour says (`controller/state`: phase, sound). A grid per
scenario is written to `docs/images/eyes-scenario-NAME.png`.

    .venv/bin/python scripts/eyes_scenarios.py [--scenarios visit,two_people]
        [--every 2.0] [--size 320x192] [--out docs/images]
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import cv2
import numpy as np

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import Collector, Process, buddybot_argv, free_port, wait_port

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]
SCENARIOS = ("visit", "passer_by", "two_people", "out_of_view")
"""The looping scenarios (`return` plays once, before the robot is up to film it)."""
ANGLE_RADAR = {"passer_by", "two_people", "out_of_view"}
"""Scenarios filmed with a simulated LD2450: the eyes can turn to a bearing."""
COLUMNS = 6
LABEL_H = 44


def world_text(world: m.SimWorld | None) -> str:
    if world is None or not world.people:
        return "nobody"
    return ", ".join(f"{p.distance_m:.1f} m {math.degrees(p.bearing_rad):+.0f} deg"
                     + (" face" if p.in_camera else "") for p in world.people)


def film(name: str, every: float, width: int, height: int, browser: Any,
         folder: Path) -> list[tuple[bytes, str, str]]:
    """One lap of `name`: (screenshot, first label line, second) every `every` s."""
    config = folder / f"{name}.toml"
    config.write_text('[audio_player]\nbackend = "null"\n'
                      + ('[radar_bridge]\nsim_model = "LD2450"\n' if name in ANGLE_RADAR
                         else ""))
    endpoint, eye_port = f"tcp/127.0.0.1:{free_port()}", free_port()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--scenario", name, "--listen",
                               endpoint, "--config", str(config), "--eye-port", str(eye_port),
                               "--dashboard-port", str(free_port()), "--status-period", "1"),
                 "up", folder / f"logs-{name}")
    shots: list[tuple[bytes, str, str]] = []
    try:
        n = len([e for e in available_services() if not e.on_request])
        up.wait_for_output(f"nodes {n}/{n}", 180)
        wait_port(eye_port, 30)
        with Node("film", robot="buddy", connect=[endpoint], probe=True) as probe:
            truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
            state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"http://127.0.0.1:{eye_port}/eyes?eye=both")
            page.wait_for_function("window.eyes && window.eyes.ready", timeout=30_000)
            first = truth.wait_for(timeout=60, what="the world")
            lap = truth.wait_for(lambda w: w.lap > first.lap, 180, "a new lap")
            start, length = time.monotonic() - lap.t_s, first_length(truth, lap)
            t = 0.0
            while t < length:
                left = start + t - time.monotonic()
                if left > 0:
                    time.sleep(left)
                world = truth.messages[-1] if truth.messages else None
                said = state.messages[-1] if state.messages else None
                behaviour = "" if said is None else said.phase + (
                    f", {said.sound}" if said.sound else "")
                shots.append((page.screenshot(), f"{name}  t={t:4.1f} s  {behaviour}",
                              world_text(world)))
                t += every
            page.close()
    finally:
        up.stop(30)
    return shots


def first_length(truth: Collector[m.SimWorld], lap: m.SimWorld) -> float:
    """The scenario's length: the time the lap before this one reached."""
    before = [w.t_s for w in truth.messages if w.lap == lap.lap - 1]
    return max(before, default=40.0)


def grid(shots: list[tuple[bytes, str, str]], width: int) -> np.ndarray:
    tiles = []
    for png, line1, line2 in shots:
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        label = np.full((LABEL_H, img.shape[1], 3), 24, np.uint8)
        for y, text in ((17, line1), (37, line2)):
            cv2.putText(label, text, (6, y), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (235, 235, 235),
                        1, cv2.LINE_AA)
        tiles.append(cv2.copyMakeBorder(np.vstack([img, label]), 2, 2, 2, 2,
                                        cv2.BORDER_CONSTANT, value=(60, 60, 60)))
    blank = np.zeros_like(tiles[0])
    while len(tiles) % COLUMNS:
        tiles.append(blank)
    rows = [np.hstack(tiles[i:i + COLUMNS]) for i in range(0, len(tiles), COLUMNS)]
    return np.vstack(rows)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--every", type=float, default=2.0, help="seconds between frames")
    parser.add_argument("--size", default="320x192", help="the eye page's size")
    parser.add_argument("--out", default="docs/images", help="folder of the PNGs")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium not installed (scripts/chromium.sh installs it)")
    from playwright.sync_api import sync_playwright

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with TemporaryDirectory() as tmp, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            for name in args.scenarios.split(","):
                shots = film(name, args.every, width, height, browser, Path(tmp))
                path = out / f"eyes-scenario-{name}.png"
                cv2.imwrite(str(path), grid(shots, width), [cv2.IMWRITE_PNG_COMPRESSION, 9])
                print(f"wrote {path} ({len(shots)} frames)")
        finally:
            browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
