#!/usr/bin/env python3
"""The web surfaces under the issue-27 floods: what a real client still gets.

Starts the dashboard, the eye renderer (`--no-browser`) and the Foxglove
bridge, each with a 1,024-descriptor limit (systemd's default soft limit),
no router needed (they serve before they join the bus). Against each:
1,100 connections that send half a request head and hold on (slow headers),
then a new request from a real client; then requests naming a foreign
`Host` and a foreign `Origin`. Prints per surface: the time the real client
waited, the flood connections still held, the log lines written, and the
median time to refuse a foreign name (421) and a foreign origin (403).

    .venv/bin/python benchmarks/web_floods.py [--flood 1100] [--limit 1024]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import results

from buddybot.tools.testing import (
    HeldSockets,
    Process,
    buddybot_argv,
    free_port,
    http_status,
    wait_port,
)

SURFACES = {
    # name: (service and its options, the page a real client asks for, the socket)
    "dashboard": (["dashboard"], "/", "/ws"),
    "eye-renderer": (["eye-renderer", "--no-browser"], "/eyes?eye=both", "/ws?eye=both"),
    "foxglove": (["foxglove"], None, "/"),
}


def refuse_ms(port: int, path: str, origin: str, host: str | None = None
              ) -> tuple[float, int]:
    """Median time (ms) of 20 refused requests, and the status they got."""
    times = []
    status = 0
    for _ in range(20):
        t0 = time.perf_counter()
        status = http_status(port, path, websocket=True, host=host, origin=origin)
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times), status


def measure(name: str, flood: int, limit: int, logs: Path) -> None:
    (service, *options), page, socket_path = SURFACES[name]
    port = free_port()
    proc = Process(buddybot_argv("run", service, "--port", str(port), "--connect",
                                 f"tcp/127.0.0.1:{free_port()}", *options),
                   name, logs, env={"DISPLAY": "", "WAYLAND_DISPLAY": ""}, nofile=limit)
    try:
        wait_port(port, 30)
        lines_before = len(proc.output().splitlines())
        held = HeldSockets(port, flood)
        try:
            t0 = time.perf_counter()
            if page is not None:
                status = http_status(port, page, timeout=30.0)
            else:
                status = http_status(port, socket_path, websocket=True, timeout=30.0)
            served_ms = (time.perf_counter() - t0) * 1000
            still = held.open_count()
        finally:
            held.close()
        host_ms, host_status = refuse_ms(port, socket_path, host=f"evil.test:{port}",
                                         origin=f"http://evil.test:{port}")
        origin_ms, origin_status = refuse_ms(port, socket_path,
                                             origin="http://evil.example")
        lines = len(proc.output().splitlines()) - lines_before
        tracebacks = proc.output().count("Traceback")
        print(f"{name}: {flood} slow-header connections under a {limit} limit "
              f"({held.failed} not connected): a new client got {status} in "
              f"{served_ms:.0f} ms; {still} flood connections still held; "
              f"{lines} log lines, {tracebacks} tracebacks; foreign Host -> {host_status} "
              f"in {host_ms:.2f} ms (median); foreign Origin -> {origin_status} in "
              f"{origin_ms:.2f} ms", flush=True)
    finally:
        proc.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flood", type=int, default=1100)
    parser.add_argument("--limit", type=int, default=1024)
    parser.add_argument("--only", choices=sorted(SURFACES), action="append")
    args = parser.parse_args()
    logs = Path(tempfile.mkdtemp(prefix="buddybot-floods-"))
    for name in args.only or SURFACES:
        measure(name, args.flood, args.limit, logs)
    print(f"logs: {logs}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
