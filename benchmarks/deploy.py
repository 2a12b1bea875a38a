"""Deployment benchmark: what TLS, client certificates and access control cost.

The same round trip through three routers on loopback, one after the other:

* ``tcp``      plain `buddybot router` (the one-host default);
* ``tls``      deploy/zenoh/router.json5 with access control switched off
               (TLS + mutual TLS only);
* ``tls+acl``  deploy/zenoh/router.json5 as shipped.

Clients use the shipped robot.json5 (identity "robot"), with certificates made by
scripts/make-test-certs.sh in a temporary folder. Figures: session set-up time
(median of several `zenoh.open`), round trip (median, p95) of a small control
message and of a 640x480 BGR image (921,600 bytes), ping here -> echo process ->
pong here, through the node runtime.

    .venv/bin/python benchmarks/deploy.py [--rounds 400] [--image-rounds 60]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import results
import zenoh
from common import ROUTES, make_message, percentile, reply_for

from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import LOOPBACK, Process, buddybot_argv, free_port, wait_port

REPO = Path(__file__).resolve().parents[1]
ZENOH_DIR = REPO / "deploy" / "zenoh"
ROBOT = "buddy"  # the id the shipped access control names
# --- the echo process ----------------------------------------------------------------


def echo_main(endpoint: str, zenoh_file: str) -> None:
    """Answer pings of both kinds until stdin closes."""
    node = Node("bench-echo", robot=ROBOT, connect=[endpoint],
                zenoh_config_file=zenoh_file or None)
    for ping, pong, ping_p, pong_p in ROUTES.values():
        pub = node.publisher(pong, **pong_p)

        def answer(msg: Any, _key: str, pub: Any = pub) -> None:
            pub.put(reply_for(msg))

        node.subscribe(ping, answer, **ping_p)
    print("READY", flush=True)
    sys.stdin.read()
    node.close()


# --- profiles ------------------------------------------------------------------------


def localized(name: str, certs: Path, work: Path, acl: bool = True) -> str:
    text = (ZENOH_DIR / f"{name}.json5").read_text().replace("/etc/buddybot/certs/",
                                                               f"{certs}/")
    if not acl:
        text = text.replace("enabled: true,", "enabled: false,", 1)
        assert "enabled: false" in text
    out = work / f"{name}{'' if acl else '-noacl'}.json5"
    out.write_text(text)
    return str(out)


def start_router(listen: str, port: int, zenoh_file: str | None, logs: Path) -> Process:
    extra = ["--zenoh-config", zenoh_file] if zenoh_file else []
    proc = Process(buddybot_argv("router", "--listen", listen, *extra), f"router-{port}", logs)
    wait_port(port)
    return proc


def setup_times(endpoint: str, zenoh_file: str | None, times: int = 7) -> list[float]:
    out = []
    for _ in range(times):
        config = zenoh_config(connect=[endpoint], base_file=zenoh_file)
        config.insert_json5("connect/timeout_ms", "10000")
        t0 = time.perf_counter()
        session = zenoh.open(config)
        out.append(time.perf_counter() - t0)
        session.close()
    return out


def round_trips(node: Node, kind: str, rounds: int) -> list[float]:
    ping, pong, ping_p, pong_p = ROUTES[kind]
    got: dict[str, int] = {"last": -1}
    cond = threading.Condition()

    def on_pong(msg: Any, _key: str) -> None:
        with cond:
            got["last"] = msg.stamp_ns
            cond.notify_all()

    node.subscribe(pong, on_pong, **pong_p)
    pub = node.publisher(ping, **ping_p)
    # Warm up until the echo answers (discovery through the router).
    deadline = time.monotonic() + 30
    while True:
        pub.put(make_message(kind, 1))
        with cond:
            if cond.wait_for(lambda: got["last"] == 1, timeout=0.5):
                break
        if time.monotonic() > deadline:
            raise TimeoutError(f"{kind}: the echo process never answered")
    messages = [make_message(kind, i) for i in range(2, rounds + 2)]
    rtts = []
    for i, msg in enumerate(messages, start=2):
        t0 = time.perf_counter()
        pub.put(msg)
        with cond:
            if not cond.wait_for(lambda i=i: got["last"] == i, timeout=5):
                raise TimeoutError(f"{kind}: pong {i} lost")
        rtts.append(time.perf_counter() - t0)
    return rtts


def run_profile(label: str, endpoint: str, port: int, router_file: str | None,
                client_file: str | None, args: argparse.Namespace, logs: Path) -> dict[str, Any]:
    router = start_router(endpoint, port, router_file, logs)
    echo = subprocess.Popen(
        [sys.executable, __file__, "--echo", endpoint, client_file or ""],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    node: Node | None = None
    try:
        assert echo.stdout is not None
        if echo.stdout.readline().strip() != "READY":
            raise RuntimeError("echo process did not start")
        result: dict[str, Any] = {"setup": setup_times(endpoint, client_file)}
        node = Node("bench-ping", robot=ROBOT, connect=[endpoint], zenoh_config_file=client_file)
        result["small"] = round_trips(node, "small", args.rounds)
        result["image"] = round_trips(node, "image", args.image_rounds)
        return result
    finally:
        if node is not None:
            node.close()
        if echo.stdin is not None:
            echo.stdin.close()
        try:
            echo.wait(10)
        except subprocess.TimeoutExpired:
            echo.kill()
        router.stop()
        print(f"  ({label} done)", file=sys.stderr)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=400, help="small-message round trips")
    parser.add_argument("--image-rounds", type=int, default=60, help="image round trips")
    parser.add_argument("--echo", nargs=2, metavar=("ENDPOINT", "ZENOH_FILE"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        echo_main(*args.echo)
        return 0

    with tempfile.TemporaryDirectory(prefix="buddybot-bench-deploy-") as tmp:
        work = Path(tmp)
        certs = work / "certs"
        subprocess.run(["bash", str(REPO / "scripts" / "make-test-certs.sh"), str(certs)],
                       check=True, capture_output=True)
        client = localized("robot", certs, work)
        profiles = {
            "tcp": (None, None, "tcp"),
            "tls": (localized("router", certs, work, acl=False), client, "tls"),
            "tls+acl": (localized("router", certs, work), client, "tls"),
        }
        results = {}
        for label, (router_file, client_file, proto) in profiles.items():
            port = free_port()
            endpoint = f"{proto}/{LOOPBACK}:{port}"
            results[label] = run_profile(label, endpoint, port, router_file, client_file, args,
                                         work / "logs")

    print(f"deploy benchmark: {args.rounds} small / {args.image_rounds} image round trips, "
          "ping -> router -> echo process -> router -> pong, node runtime, 127.0.0.1")
    print(f"{'profile':<9} {'session setup':>14} {'small median':>13} {'small p95':>10} "
          f"{'image median':>13} {'image p95':>10}")
    for label, r in results.items():
        print(f"{label:<9} {statistics.median(r['setup']) * 1e3:>11.1f} ms "
              f"{statistics.median(r['small']) * 1e3:>10.3f} ms "
              f"{percentile(r['small'], 0.95) * 1e3:>7.3f} ms "
              f"{statistics.median(r['image']) * 1e3:>10.2f} ms "
              f"{percentile(r['image'], 0.95) * 1e3:>7.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
