"""`bot.params`: a running node's live parameters over `params/<node>`.

The node validates a change against its own settings type
(services/runtime/params.py) and refuses it as a whole with its reason,
which becomes `Refused`; a node that does not answer is `NoService`.
`offer` is the other side: a program's own settings, live for everyone.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.params import LiveSettings
from buddybot.sdk.calls import call
from buddybot.sdk.errors import Refused

S = TypeVar("S", bound=msgspec.Struct)


class Params:
    def __init__(self, node: Node, timeout: float) -> None:
        self.node = node
        self.timeout = timeout

    def _call(self, node_name: str, request: m.ParamRequest, timeout: float | None
              ) -> m.ParamReply:
        if not keys.valid_robot_id(node_name):
            raise ValueError(f"{node_name!r} is not a node name")
        limit = self.timeout if timeout is None else timeout
        reply: m.ParamReply = call(self.node, keys.PARAMS, request, limit,
                                   hint=f"node {node_name} is not running, or it exposes no "
                                   "parameters", node=node_name)
        if reply.error:
            raise Refused(f"{node_name}: {reply.error}")
        return reply

    def get(self, node: str, field: str, timeout: float | None = None) -> Any:
        """The value `node` runs with for `field` (plain JSON types)."""
        reply = self._call(node, m.ParamRequest(op="get", name=field), timeout)
        return reply.params[0].value

    def set(self, node: str, field: str, value: Any, timeout: float | None = None) -> bool:
        """Set a live field; True when the value changed (False: it had it already)."""
        reply = self._call(node, m.ParamRequest(op="set", values={field: value}), timeout)
        return bool(reply.changed)

    def offer(self, settings: S, apply: Callable[[S], None]) -> None:
        """Offer `settings` (a msgspec Struct) as this program's parameters on
        `params/<its name>`: `buddybot param set`, the dashboard and
        `bot.params.set` change the fields marked live
        (`msgspec.Meta(extra={"live": True})`); each valid change is handed to
        `apply(new)`, whose exception refuses it (the old settings stay)."""
        LiveSettings(settings, apply).serve(self.node)
