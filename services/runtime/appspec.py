"""How an app is named on a command line or in `[apps]`: FILE, MODULE or NAME.

Pure text rules, shared by the config check (`[apps] run`, at start-up) and
the loader (`buddybot.apps.loading`), so a typo is refused the same way in
both places before anything is imported:

* FILE: a path ending in `.py` (`examples/apps/greeter.py`), optionally
  `FILE:Class` to pick one class of several;
* MODULE: a dotted import path (`mypkg.app`), optionally `mypkg.app:Class`;
* NAME: one word (`greeter`): an app installed under the `buddybot.apps`
  entry-point group, else a top-level module of that name.

The default node name of an app comes from its spec too (the file's stem,
the module's last part, the entry point's name), so `up` knows the name of
an app it supervises without importing the app's code.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

_IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
_MODULE = re.compile(rf"^{_IDENT}(\.{_IDENT})+$")
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
_CLASS = re.compile(rf"^{_IDENT}$")
_NODE_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")

Kind = Literal["file", "module", "name"]


@dataclass(frozen=True)
class AppSpec:
    kind: Kind
    target: str
    """The path, the dotted module, or the entry-point name."""
    cls: str | None = None
    """The class asked for (`:Class`), None: the module's one app class."""

    @property
    def default_name(self) -> str:
        """The app's node name unless its class says otherwise (`App.name`)."""
        if self.kind == "file":
            stem = self.target.replace("\\", "/").rsplit("/", 1)[-1].removesuffix(".py")
        elif self.kind == "module":
            stem = self.target.rsplit(".", 1)[-1]
        else:
            stem = self.target
        return node_name(stem)

    def __str__(self) -> str:
        return self.target + (f":{self.cls}" if self.cls else "")


def node_name(text: str) -> str:
    """`text` made a valid node name (letters, digits, `-`, `_`); `app` if nothing is left."""
    return _NODE_UNSAFE.sub("-", text).strip("-") or "app"


def parse_app_spec(text: str) -> AppSpec:
    """Classify `text`, or ValueError saying what an app spec looks like."""
    spec = text.strip()
    if not spec:
        raise ValueError("an empty app (give FILE.py, pkg.module or an installed app's NAME)")
    target, cls = spec, None
    head, sep, tail = spec.rpartition(":")
    if sep and "/" not in tail and "\\" not in tail and not (len(head) == 1 and head.isalpha()):
        target, cls = head, tail
        if not _CLASS.match(cls):
            raise ValueError(f"{text!r}: {cls!r} after ':' is not a class name")
    if target.endswith(".py") or "/" in target or "\\" in target:
        if not target.endswith(".py"):
            raise ValueError(f"{text!r}: an app file must end in .py")
        return AppSpec("file", target, cls)
    if _MODULE.match(target):
        return AppSpec("module", target, cls)
    if cls is None and _NAME.match(target) and "." not in target:
        return AppSpec("name", target)
    if re.match(rf"^{_IDENT}$", target):
        return AppSpec("module", target, cls)
    raise ValueError(f"{text!r} is not an app: give FILE.py[:Class], pkg.module[:Class] "
                     "or an installed app's NAME")
