"""Live parameters: a service's settings struct, readable and settable while it runs.

A field is *live* (a change applies at once) when its `msgspec.Meta` carries
`extra={"live": True}`, beside its range and description: the settings struct
stays the one source of truth, with no second list to keep in step.

`LiveSettings` holds the current struct. A change is validated as the config
file is (`msgspec.convert`: range, type, `__post_init__`), refused whole when a
value is bad or names a restart-only field (never kept "pending", invisible
state: the config file is where a restart-time value belongs), then handed to
the service's `apply(new_settings)`. `serve(node)` answers `params/<node>`
(`keys.PARAMS`); each change is logged at INFO and counted in diagnostics
(`params_changed`, `last_param_change`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import msgspec
import msgspec.inspect as mi

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.limits import clip
from buddybot.runtime.overrides import annotation, describe_range, struct_fields, table_of

S = TypeVar("S", bound=msgspec.Struct)

LIVE = "live"
"""The key of `msgspec.Meta(extra=...)` that marks a field as live."""

log = logging.getLogger("buddybot.params")


class ParamRefused(ValueError):
    """A change the settings type or the running service does not accept.

    `unknown`: the request named a field the table does not have."""

    def __init__(self, text: str, *, unknown: bool = False) -> None:
        super().__init__(text)
        self.unknown = unknown


# --- what the struct says about a field -------------------------------------------


def _metadata(t: mi.Type) -> list[mi.Metadata]:
    """Every Meta wrapper of a field's type, also inside `X | None`."""
    found: list[mi.Metadata] = []
    while isinstance(t, mi.Metadata):
        found.append(t)
        t = t.type
    if isinstance(t, mi.UnionType):
        for member in t.types:
            found.extend(_metadata(member))
    return found


def is_live(struct: type[msgspec.Struct], field: str) -> bool:
    """Whether `struct.field` is marked live (`msgspec.Meta(extra={"live": True})`)."""
    for f in struct_fields(struct):
        if f.name == field:
            return any(bool((meta.extra or {}).get(LIVE)) for meta in _metadata(f.type))
    raise KeyError(f"{struct.__name__} has no field {field!r}")


def live_fields(struct: type[msgspec.Struct]) -> list[str]:
    return [f.name for f in struct_fields(struct) if is_live(struct, f.name)]


def _description(t: mi.Type) -> str:
    for meta in _metadata(t):
        text = (meta.extra_json_schema or {}).get("description")
        if text:
            return str(text)
    return ""


def _type_name(hint: Any) -> str:
    """`float`, `str | None`, `list[str]`: the annotation without its Meta."""
    text = repr(hint)
    if hasattr(hint, "__metadata__"):  # Annotated[X, Meta]
        return _type_name(hint.__origin__)
    if isinstance(hint, type):
        return hint.__name__
    return text.replace("typing.", "")


def describe(settings: msgspec.Struct) -> list[m.ParamInfo]:
    """Every field of `settings` with its value, type, range and live mark."""
    struct = type(settings)
    values = msgspec.to_builtins(settings)
    return [
        m.ParamInfo(
            name=f.name, value=values.get(f.name), type=_type_name(annotation(struct, f.name)),
            range=describe_range(f.type), live=is_live(struct, f.name),
            description=_description(f.type),
        )
        for f in struct_fields(struct)
    ]


def validate(current: S, values: dict[str, Any]) -> tuple[S, list[str]]:
    """`current` with `values` applied, checked like the config file; and the
    fields that actually change. Raises ParamRefused naming the field and what
    it allows; a restart-only field may only be "set" to the value it has."""
    struct = type(current)
    names = {f.name: f for f in struct_fields(struct)}
    table = table_of(struct)
    for name in values:
        if name not in names:
            raise ParamRefused(f"[{table}] has no parameter {clip(name, 80)!r} "
                               f"(known: {', '.join(names)})", unknown=True)
    now = msgspec.to_builtins(current)
    changed: list[str] = []
    typed_values: dict[str, Any] = {}
    for name, value in values.items():
        try:
            typed = msgspec.convert(value, annotation(struct, name))
        except msgspec.ValidationError as exc:
            bounds = describe_range(names[name].type)
            text = str(exc)
            if " - at `$" in text or ", got `" in text:  # a wrong type, or a bad item
                allowed = text.replace("`$", f"`{name}")
            else:
                allowed = f"allowed {bounds}" if bounds else text.replace("`$`", "value")
            raise ParamRefused(f"{table}.{name} = {clip(repr(value), 80)} refused: "
                               f"{allowed}") from None
        typed_values[name] = msgspec.to_builtins(typed)
        if typed_values[name] == now.get(name):
            continue
        if not is_live(struct, name):
            raise ParamRefused(f"{table}.{name} needs a restart: change it in the config "
                               "file and restart the service (not applied)")
        changed.append(name)
    merged = {**now, **typed_values}
    try:  # the whole struct: cross-field checks (`__post_init__`) run too
        new = msgspec.convert(merged, struct)
    except msgspec.ValidationError as exc:
        raise ParamRefused(f"[{table}] refused: {exc}") from None
    return new, changed


# --- the holder -------------------------------------------------------------------


class LiveSettings(Generic[S]):
    """The settings a running service uses now, and the one way to change them.

    `apply(new)` is the service's callback: it swaps the struct its logic
    reads (under the service's own lock). If it raises, the change is
    refused and the old struct stays. `current` is always a complete,
    validated struct, so a service may also read it on every use instead.
    """

    def __init__(self, settings: S, apply: Callable[[S], None] | None = None) -> None:
        self._current = settings
        self._apply = apply
        self._lock = threading.Lock()
        self.changes = 0
        self.last_change = ""
        self.table = table_of(type(settings))

    @property
    def current(self) -> S:
        return self._current

    def describe(self) -> list[m.ParamInfo]:
        return describe(self._current)

    def set(self, values: dict[str, Any]) -> list[str]:
        """Validate and apply `values` together; the names that changed.
        Raises ParamRefused (nothing applied) when one is refused."""
        with self._lock:
            new, changed = validate(self._current, values)
            if not changed:
                return []
            if self._apply is not None:
                try:
                    self._apply(new)
                except Exception as exc:
                    raise ParamRefused(f"[{self.table}] the service refused the change: "
                                       f"{clip(str(exc) or repr(exc), 200)}") from None
            self._current = new
            self.changes += 1
            now = msgspec.to_builtins(new)
            self.last_change = clip(", ".join(f"{n}={now[n]!r}" for n in changed), 200)
            return changed

    # -- on the bus --

    def handle(self, node_name: str, request: m.ParamRequest) -> m.ParamReply:
        """One `params/<node>` request -> its reply (pure: testable without Zenoh)."""
        reply = m.ParamReply(node=node_name, table=self.table)
        try:
            if request.op == "set":
                reply.changed = self.set(dict(request.values))
                reply.params = [p for p in self.describe() if p.name in request.values]
            elif request.op == "get":
                reply.params = [p for p in self.describe() if p.name == request.name]
                if not reply.params:
                    raise ParamRefused(f"[{self.table}] has no parameter "
                                       f"{clip(request.name, 80)!r}", unknown=True)
            else:
                reply.params = self.describe()
        except ParamRefused as exc:
            reply.error = str(exc)
            reply.unknown = exc.unknown
        return reply

    def serve(self, node: Any) -> Any:
        """Answer `params/<node>` on `node` (a `Node`); every change is logged at
        INFO and counted in its diagnostics. Returns the queryable handle."""

        def on_request(request: m.ParamRequest) -> m.ParamReply:
            reply = self.handle(node.name, request)
            if reply.changed:
                node.diagnostics.increment("params_changed")
                node.diagnostics.values["last_param_change"] = self.last_change
                node.log.info("parameters changed: %s", self.last_change)
            elif reply.error and request.op == "set":
                node.log.info("parameter change refused: %s", clip(reply.error, 200))
            return reply

        return node.serve(keys.PARAMS, on_request, node=node.name)
