"""zenoh-cli decoder plugin: `zenoh subscribe -k 'buddybot/**' --decoder buddybot`.

Registered under the entry point group `zenoh_cli.codecs.decoders`.
"""

from __future__ import annotations

from typing import Any

from buddybot.contract.describe import describe


def decode(key: Any, payload: bytes) -> str:
    """zenoh-cli passes a `zenoh.KeyExpr`; `str()` gives the key text."""
    return describe(str(key), bytes(payload))
