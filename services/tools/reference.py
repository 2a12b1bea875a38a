"""Generate the reference pages of `docs/reference/` from the code itself.

The keys come from the key catalogue, the messages and enums from the
msgspec structs of `buddybot.contract.messages`, the config keys from every
settings struct (type, default, range and the live mark of
`buddybot.runtime.params`), the verbs from the argparse parsers. Written
by `buddybot reference`; `buddybot reference --check` (run by
scripts/test.sh and a test) fails when a committed page differs from what
the code says, so the reference cannot drift from the code.

A field's description is its `msgspec.Meta(description=...)`, else the
first paragraph of the docstring under it in the source (read with `ast`:
Python keeps no attribute docstrings at run time).
"""

from __future__ import annotations

import argparse
import ast
import enum
import functools
import inspect
import json
import textwrap
from collections.abc import Callable, Iterable
from pathlib import Path

import msgspec
import msgspec.inspect as mi

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.contract.schemas import stale_files, write_files
from buddybot.runtime import config, params, registry
from buddybot.runtime.overrides import describe_range

OUT = Path("docs/reference")
GENERATED = ("This page is generated from the code by `buddybot reference`; "
             "`buddybot reference --check` fails when it is out of date. Do not edit it.")


# --- what the source says about a field ---------------------------------------------


@functools.cache
def attribute_docs(cls: type) -> dict[str, str]:
    """Field name -> first paragraph of the string literal right under it in `cls`."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    body = ast.parse(source).body[0]
    assert isinstance(body, ast.ClassDef)
    docs: dict[str, str] = {}
    for before, after in zip(body.body, body.body[1:], strict=False):
        if (isinstance(before, ast.AnnAssign) and isinstance(before.target, ast.Name)
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):
            docs[before.target.id] = paragraph(after.value.value)
    return docs


def paragraph(text: str | None) -> str:
    """The first paragraph of a docstring, on one line."""
    if not text:
        return ""
    first = inspect.cleandoc(text).split("\n\n")[0]
    return " ".join(first.split())


def meta_description(t: mi.Type) -> str:
    while isinstance(t, mi.Metadata):
        text = (t.extra_json_schema or {}).get("description")
        if text:
            return str(text)
        t = t.type
    if isinstance(t, mi.UnionType):
        return next((d for d in map(meta_description, t.types) if d), "")
    return ""


def type_text(t: mi.Type) -> str:
    """A field's type as a reader writes it: `float`, `str | None`, `list[Person]`."""
    while isinstance(t, mi.Metadata):
        t = t.type
    simple: dict[type, str] = {mi.IntType: "int", mi.FloatType: "float", mi.StrType: "str",
                               mi.BoolType: "bool", mi.BytesType: "bytes",
                               mi.NoneType: "None", mi.AnyType: "any"}
    if type(t) in simple:
        return simple[type(t)]
    if isinstance(t, mi.UnionType):
        return " | ".join(type_text(x) for x in t.types)
    if isinstance(t, (mi.ListType, mi.VarTupleType, mi.SetType, mi.FrozenSetType)):
        name = {mi.ListType: "list", mi.VarTupleType: "tuple", mi.SetType: "set",
                mi.FrozenSetType: "frozenset"}[type(t)]
        return f"{name}[{type_text(t.item_type)}]"
    if isinstance(t, mi.TupleType):
        return f"tuple[{', '.join(type_text(x) for x in t.item_types)}]"
    if isinstance(t, mi.DictType):
        return f"dict[{type_text(t.key_type)}, {type_text(t.value_type)}]"
    if isinstance(t, mi.LiteralType):
        return " | ".join(json.dumps(v) for v in t.values)
    if isinstance(t, (mi.StructType, mi.EnumType)):
        return t.cls.__name__
    return type(t).__name__.removesuffix("Type").lower()


def default_text(field: msgspec.structs.FieldInfo) -> str:
    if field.default is not msgspec.NODEFAULT:
        value = field.default
    elif field.default_factory is not msgspec.NODEFAULT:
        value = field.default_factory()
    else:
        return "required"
    if isinstance(value, enum.Enum):
        return f"{value.name} ({value.value})" if isinstance(value, int) else value.name
    return f"`{json.dumps(msgspec.to_builtins(value))}`"


def cell(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return text.replace("|", "\\|").replace("\n", " ")


def table(header: Iterable[str], rows: Iterable[Iterable[str]]) -> list[str]:
    head = list(header)
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return lines


def page(title: str, audience: str, body: list[str]) -> str:
    return "\n".join([f"# {title}", "", audience, "", f"_{GENERATED}_", "", *body]).rstrip() + "\n"


def struct_rows(cls: type[msgspec.Struct], extra: Callable[[str], list[str]] | None = None
                ) -> list[list[str]]:
    info = mi.type_info(cls)
    assert isinstance(info, mi.StructType)
    fields = {f.name: f for f in msgspec.structs.fields(cls)}
    docs = attribute_docs(cls)
    rows = []
    for f in info.fields:
        row = [f"`{f.name}`", f"`{type_text(f.type)}`", default_text(fields[f.name]),
               describe_range(f.type)]
        if extra is not None:
            row += extra(f.name)
        row.append(meta_description(f.type) or docs.get(f.name, ""))
        rows.append(row)
    return rows


# --- the pages ----------------------------------------------------------------------


def keys_page() -> str:
    body = ["Every key is relative to `buddybot/<robot>/` (`buddybot keys` prints the same "
            "catalogue; `schemas/keys.json` holds it as data). Message types: "
            "[messages.md](messages.md).", ""]
    rows = []
    for row in keys.key_table():
        if row["kind"] == "service":
            what = f"[{row['request']}](messages.md#{row['request'].lower()}) -> " \
                   f"[{row['reply']}](messages.md#{row['reply'].lower()})"
        elif row["kind"] == "topic":
            what = f"[{row['type']}](messages.md#{row['type'].lower()})"
            if row.get("latched"):
                what += " (latched)"
        else:
            what = ""
        rows.append([f"`{row['key']}`", row["kind"], what, row.get("encoding", ""),
                     paragraph(row.get("doc"))])
    body += table(["key", "kind", "message", "encoding", "what it carries"], rows)
    return page("Keys", "For builders writing a program, app or device that talks to the "
                "robot: every key on the bus.", body)


def int_enums() -> list[type[enum.IntEnum]]:
    return [v for v in vars(m).values() if isinstance(v, type) and issubclass(v, enum.IntEnum)
            and v is not enum.IntEnum and v.__module__ == m.__name__]


def messages_page() -> str:
    body = ["Every message is a msgspec struct of `buddybot.contract.messages`, sent as "
            "JSON (images as CBOR); `schemas/messages/` holds their JSON Schemas. A "
            "field without default is required; an unknown field is refused. Enums: "
            "[enums.md](enums.md).", ""]
    for cls in m.ALL_MESSAGES:
        body += [f"## {cls.__name__}", ""]
        doc = paragraph(cls.__doc__)
        if doc:
            body += [doc, ""]
        body += table(["field", "type", "default", "range", "description"], struct_rows(cls))
        body.append("")
    return page("Messages", "For builders writing a program or device that reads or "
                "sends the robot's messages: every message and its fields.", body)


def enums_page() -> str:
    body = ["On the wire an enum is its number; `buddybot pub`, `echo` and the SDK "
            "also take and show its name.", ""]
    for cls in int_enums():
        body += [f"## {cls.__name__}", ""]
        doc = paragraph(cls.__doc__) if cls.__doc__ != enum.IntEnum.__doc__ else ""
        if doc and "An enumeration" not in doc:
            body += [doc, ""]
        body += table(["number", "name"], [[str(v.value), f"`{v.name}`"] for v in cls])
        body.append("")
    return page("Enums", "For builders sending commands (an expression, an eye) who need "
                "the names and numbers of every enum.", body)


def config_tables() -> list[tuple[str, type[msgspec.Struct]]]:
    shared = [(f.name, f.type) for f in msgspec.structs.fields(config.ConfigBase)
              if isinstance(f.type, type) and issubclass(f.type, msgspec.Struct)]
    return shared + [(e.table, e.settings_type()) for e in registry.SERVICES
                     if e.table is not None]


def config_page() -> str:
    body = ["The robot reads one TOML file (`--config FILE` or `$BUDDYBOT_CONFIG`), one "
            "table per service; every key has a default, an unknown key or a wrong type "
            "stops the service at start with the key named. *live*: `buddybot param set "
            "NODE KEY VALUE` changes it while the service runs; *restart*: change the "
            "file and restart the service. `buddybot config` prints the effective values.",
            ""]
    for name, cls in config_tables():
        body += [f"## [{name}]", ""]
        doc = paragraph(cls.__doc__)
        if doc:
            body += [doc, ""]

        def live(field: str, cls: type[msgspec.Struct] = cls) -> list[str]:
            return ["live" if params.is_live(cls, field) else "restart"]

        body += table(["key", "type", "default", "range", "change", "description"],
                      struct_rows(cls, live))
        body.append("")
    return page("Configuration keys", "For builders writing or tuning `robot.toml`: "
                "every table and key, its type, default, range and whether it is live.", body)


def _fixed_width(parser: argparse.ArgumentParser) -> None:
    """Usage lines that do not depend on the terminal the generator runs in."""
    parser.formatter_class = functools.partial(
        argparse.RawDescriptionHelpFormatter, width=100)


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_rows(parser: argparse.ArgumentParser) -> list[list[str]]:
    formatter = argparse.HelpFormatter(parser.prog, width=100)
    rows = []
    for action in parser._actions:
        if (isinstance(action, (argparse._HelpAction, argparse._SubParsersAction))
                or action.help == argparse.SUPPRESS):
            continue
        name = ", ".join(action.option_strings) or (action.metavar or action.dest)
        if action.choices is not None and not isinstance(action.choices, dict):
            values = ", ".join(str(c) for c in action.choices)
        elif action.nargs == 0:
            values = ""
        else:
            values = str(action.metavar or (action.dest.upper() if action.option_strings
                                            else ""))
        default = action.default
        shown = "" if default in (None, False, argparse.SUPPRESS) or action.nargs == 0 \
            else f"`{default}`"
        helptext = formatter._expand_help(action) if action.help else ""
        rows.append([f"`{name}`", values, shown, " ".join(helptext.split())])
    return rows


def _verb_section(title: str, parser: argparse.ArgumentParser, level: str) -> list[str]:
    _fixed_width(parser)
    lines = [f"{level} {title}", ""]
    if parser.description:
        lines += [paragraph(parser.description), ""]
    lines += ["```", parser.format_usage().strip(), "```", ""]
    rows = _option_rows(parser)
    if rows:
        lines += [*table(["argument", "values", "default", "what it does"], rows), ""]
    for name, sub in _subparsers(parser).items():
        lines += _verb_section(f"{title} {name}", sub, level + "#")
    return lines


def cli_page(parser: argparse.ArgumentParser, extensions: list[tuple[str, argparse.ArgumentParser]]
             ) -> str:
    """`parser`: the `buddybot` parser; `extensions`: (`run SERVICE` or tool, its parser)."""
    body = ["Exit status: 0 success, 1 failure at run time, 2 bad usage or config. "
            "`buddybot VERB --help` prints the same.", ""]
    for name, sub in _subparsers(parser).items():
        if name == "run" or any(name == t.name for t in registry.TOOLS):
            continue
        body += _verb_section(f"buddybot {name}", sub, "##")
    for title, sub in extensions:
        body += _verb_section(title, sub, "##")
    return page("Command line", "For builders running and probing the robot: every "
                "`buddybot` verb and its options.", body)


def index_page(names: Iterable[str]) -> str:
    titles = {"keys.md": "every key on the bus", "messages.md": "every message and field",
              "enums.md": "enum names and numbers", "config.md": "every configuration key",
              "cli.md": "every `buddybot` verb", "processes.md":
              "writing your own process: callbacks, nodes, liveliness"}
    body = [f"- [{n}]({n}): {titles.get(n, '')}" for n in names]
    return page("Reference", "For builders who know what they look for: the exact keys, "
                "messages, enums, configuration and commands.", body)


def generate(parser: argparse.ArgumentParser,
             extensions: list[tuple[str, argparse.ArgumentParser]]) -> dict[str, str]:
    """File name (relative to docs/reference/) -> content."""
    files = {"keys.md": keys_page(), "messages.md": messages_page(), "enums.md": enums_page(),
             "config.md": config_page(), "cli.md": cli_page(parser, extensions)}
    files["README.md"] = index_page([*files, "processes.md"])
    return files


def write(out: Path, files: dict[str, str]) -> list[Path]:
    return write_files(out, files)


def drift(out: Path, files: dict[str, str]) -> list[str]:
    """Generated pages that are missing or differ from the code (hand-written
    pages of the folder are not checked here)."""
    return stale_files(out, files, "*.never")
