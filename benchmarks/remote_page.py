#!/usr/bin/env python3
"""A stand-in for a dashboard page opened on a laptop: reads what the page reads.

The dashboard is meant to be opened from another computer, so the robot pays
for the dashboard service and the eye renderer's extra page, not for the
browser that draws them. This reader opens the same two WebSockets a page
opens (the dashboard's `/ws`, which streams the camera images while a page is
connected, and the eye page's `/ws?eye=both` of the mirrored eyes) and reads
everything as fast as it comes, as a browser would, but draws nothing.

It runs until SIGTERM or SIGINT and then prints one JSON line with what it
received: `{"images": N, "messages": N, "eye_messages": N, "seconds": S}`.

    .venv/bin/python benchmarks/remote_page.py --dashboard-port P --eye-port Q
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import time

import aiohttp


async def read(url: str, counts: dict[str, int], text_key: str) -> None:
    """Read one WebSocket until cancelled; reconnect if the server drops it."""
    async with aiohttp.ClientSession() as session:
        while True:
            try:
                async with session.ws_connect(url, heartbeat=10.0, max_msg_size=0) as ws:
                    async for msg in ws:
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            counts["images"] += 1
                        elif msg.type == aiohttp.WSMsgType.TEXT:
                            counts[text_key] += 1
            except aiohttp.ClientError:
                pass
            await asyncio.sleep(0.2)


async def main(args: argparse.Namespace) -> None:
    counts = {"images": 0, "messages": 0, "eye_messages": 0}
    started = time.monotonic()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    tasks = [
        asyncio.create_task(read(f"ws://127.0.0.1:{args.dashboard_port}/ws", counts,
                                 "messages")),
        asyncio.create_task(read(f"ws://127.0.0.1:{args.eye_port}/ws?eye=both", counts,
                                 "eye_messages")),
    ]
    print("reading", flush=True)
    await stop.wait()
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    print(json.dumps({**counts, "seconds": round(time.monotonic() - started, 2)}), flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dashboard-port", type=int, required=True)
    parser.add_argument("--eye-port", type=int, required=True)
    asyncio.run(main(parser.parse_args()))
