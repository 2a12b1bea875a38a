"""A minimal node process for runtime tests: subscribes to every catalogue topic.

Run as `python node_process.py ENDPOINT NAME`; it prints READY once
subscribed and exits on SIGTERM. It is what a service is, minus a job.
"""

from __future__ import annotations

import sys
import threading

from buddybot.contract import keys
from buddybot.runtime.node import Node, install_signal_handlers
from buddybot.runtime.service import setup_logging


def main() -> None:
    endpoint, name = sys.argv[1], sys.argv[2]
    setup_logging("INFO")
    stop = threading.Event()
    install_signal_handlers(stop)
    node = Node(name, connect=[endpoint], stop_event=stop, diagnostics_period_s=0.5)
    received = {"n": 0}

    def on_message(_msg: object, _key: str) -> None:
        received["n"] += 1
        node.diagnostics.values["received"] = received["n"]

    for topic in keys.TOPICS:
        node.subscribe(topic, on_message)
    print("READY", flush=True)
    try:
        node.spin()
    finally:
        node.close()


if __name__ == "__main__":
    main()
