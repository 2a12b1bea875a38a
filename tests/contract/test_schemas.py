"""schemas/ is generated from the types; it must not drift, and it must say what
the decoder really accepts.

Drift alone is not enough: `drift` compares the committed files with the
generator, so a generator that wrote the wrong thing would pass. The
checks below therefore hold the *committed* files against facts that do
not come from the generator: real encoded messages must validate, and for
payloads broken one field at a time (from the types' own constraints, via
`msgspec.inspect`) the schema and the runtime decoder must give the same
verdict. A non-Python peer building against schemas/ then sends what the
robot accepts.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import msgspec
import pytest

from buddybot.contract import keys, schemas
from buddybot.contract import messages as m
from tests.contract.test_messages import sample_messages

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "schemas"
JSON_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool}
# Keywords that do not constrain an instance; any other unknown keyword fails the
# test, so the little validator below can never skip a constraint silently.
ANNOTATIONS = {"$defs", "title", "description", "default", "examples", "contentEncoding",
               "x-enum-names"}


# --- a small JSON Schema validator (the subset msgspec emits) --------------------------


def schema_errors(value: Any, schema: dict[str, Any], root: dict[str, Any],
                  path: str = "$") -> list[str]:
    """Why `value` does not match `schema` (empty: it matches)."""
    errors: list[str] = []
    for word, arg in schema.items():
        if word in ANNOTATIONS:
            continue
        if word == "$ref":
            target = root
            for part in arg.removeprefix("#/").split("/"):
                target = target[part]
            errors += schema_errors(value, target, root, path)
        elif word == "anyOf":
            if all(schema_errors(value, option, root, path) for option in arg):
                errors.append(f"{path}: matches no anyOf option")
        elif word == "type":
            if not _is_type(value, arg):
                errors.append(f"{path}: not of type {arg}")
        elif word == "enum":
            if not any(_same(value, option) for option in arg):
                errors.append(f"{path}: {value!r} not in {arg}")
        elif word in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
            if _is_number(value) and not _bound_ok(word, value, arg):
                errors.append(f"{path}: {value!r} violates {word} {arg}")
        elif word in ("minLength", "maxLength"):
            if isinstance(value, str) and not _size_ok(word, len(value), arg):
                errors.append(f"{path}: length {len(value)} violates {word} {arg}")
        elif word in ("minItems", "maxItems"):
            if isinstance(value, list) and not _size_ok(word, len(value), arg):
                errors.append(f"{path}: {len(value)} items violate {word} {arg}")
        elif word in ("minProperties", "maxProperties"):
            if isinstance(value, dict) and not _size_ok(word, len(value), arg):
                errors.append(f"{path}: {len(value)} properties violate {word} {arg}")
        elif word == "items":
            if isinstance(value, list):
                for i, item in enumerate(value):
                    errors += schema_errors(item, arg, root, f"{path}[{i}]")
        elif word == "required":
            if isinstance(value, dict):
                errors += [f"{path}: missing {name}" for name in arg if name not in value]
        elif word == "properties":
            if isinstance(value, dict):
                for name, sub in arg.items():
                    if name in value:
                        errors += schema_errors(value[name], sub, root, f"{path}.{name}")
        elif word == "propertyNames":
            if isinstance(value, dict):
                for name in value:
                    errors += schema_errors(name, arg, root, f"{path}[key {name!r}]")
        elif word == "additionalProperties":
            if isinstance(value, dict):
                known = set(schema.get("properties", {}))
                for name in value.keys() - known:
                    if arg is False:
                        errors.append(f"{path}: unknown field {name}")
                    elif isinstance(arg, dict):
                        errors += schema_errors(value[name], arg, root, f"{path}.{name}")
        else:
            raise AssertionError(f"validator does not know JSON Schema keyword {word!r}")
    return errors


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _is_type(value: Any, name: str) -> bool:
    if name == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if name == "number":
        return _is_number(value)
    if name == "null":
        return value is None
    return isinstance(value, JSON_TYPES[name])


def _same(a: Any, b: Any) -> bool:
    return (type(a) is type(b) and a == b) or (_is_number(a) and _is_number(b) and a == b)


def _bound_ok(word: str, value: float, bound: float) -> bool:
    return {"minimum": value >= bound, "maximum": value <= bound,
            "exclusiveMinimum": value > bound, "exclusiveMaximum": value < bound}[word]


def _size_ok(word: str, size: int, bound: int) -> bool:
    return size >= bound if word.startswith("min") else size <= bound


def committed_schema(msg_type: type[m.Message]) -> dict[str, Any]:
    path = COMMITTED / "messages" / f"{msg_type.__name__}.json"
    return json.loads(path.read_text())  # type: ignore[no-any-return]


def decoder_accepts(msg_type: type[m.Message], payload: dict[str, Any]) -> bool:
    try:
        msgspec.json.decode(json.dumps(payload).encode(), type=msg_type)
    except msgspec.ValidationError:
        return False
    return True


# --- payloads broken one field at a time, from the types (not from the schema) --------


def _unwrap(info: msgspec.inspect.Type) -> msgspec.inspect.Type:
    while isinstance(info, msgspec.inspect.Metadata):
        info = info.type
    if isinstance(info, msgspec.inspect.UnionType):
        concrete = [t for t in info.types if not isinstance(t, msgspec.inspect.NoneType)]
        if len(concrete) == 1:
            return _unwrap(concrete[0])
    return info


def _outside_values(info: msgspec.inspect.Type) -> list[Any]:
    """Values just outside what the type allows (plus one of a wrong JSON type);
    none for a field that takes any value (a parameter's value)."""
    t = _unwrap(info)
    if isinstance(t, msgspec.inspect.AnyType):
        return []
    # Of a wrong JSON type: a list where a string is expected (str, bytes as base64,
    # literals, unions with str), else a string.
    stringy = (msgspec.inspect.StrType | msgspec.inspect.BytesType
               | msgspec.inspect.LiteralType | msgspec.inspect.UnionType)
    out: list[Any] = [[]] if isinstance(t, stringy) else ["a string"]
    if isinstance(t, msgspec.inspect.IntType | msgspec.inspect.FloatType):
        step = 1 if isinstance(t, msgspec.inspect.IntType) else 0.5
        out += [x for x in (
            None if t.ge is None else t.ge - step, t.gt,
            None if t.le is None else t.le + step, t.lt) if x is not None]
    elif isinstance(t, msgspec.inspect.StrType):
        if t.max_length is not None:
            out.append("x" * (t.max_length + 1))
        if t.min_length:
            out.append("")
    elif isinstance(t, msgspec.inspect.EnumType):
        out.append(max(int(v) for v in t.cls) + 100)
    elif isinstance(t, msgspec.inspect.LiteralType):
        out.append("NOT_ONE_OF_THEM")
    elif isinstance(t, msgspec.inspect.DictType) and t.max_length is not None:
        out.append({f"k{i}": 0 for i in range(t.max_length + 1)})
    return out


def broken_payloads() -> list[tuple[str, type[m.Message], dict[str, Any], bool]]:
    """(id, type, payload, invalid): `invalid` unless only an optional field is missing."""
    cases: list[tuple[str, type[m.Message], dict[str, Any], bool]] = []
    for sample in sample_messages():
        msg_type = type(sample)
        good = json.loads(msgspec.json.encode(sample))
        cases.append((f"{msg_type.__name__}+unknown", msg_type, {**good, "unknown_field": 1}, True))
        info = msgspec.inspect.type_info(msg_type)
        assert isinstance(info, msgspec.inspect.StructType)
        for field in info.fields:
            name = field.encode_name
            if name in good:
                cases.append((f"{msg_type.__name__}-{name}", msg_type,
                              {k: v for k, v in good.items() if k != name}, field.required))
            for i, bad in enumerate(_outside_values(field.type)):
                cases.append((f"{msg_type.__name__}.{name}#{i}", msg_type,
                              {**good, name: bad}, True))
    return cases


BROKEN = broken_payloads()


# --- the tests ---------------------------------------------------------------------------


def test_committed_schemas_match_the_types() -> None:
    stale = schemas.drift(COMMITTED)
    assert stale == [], f"run `buddybot schemas` to regenerate: {stale}"


@pytest.mark.parametrize("msg", sample_messages(), ids=lambda x: type(x).__name__)
def test_real_encoded_messages_validate_against_the_committed_schema(msg: m.Message) -> None:
    schema = committed_schema(type(msg))
    payload = json.loads(msgspec.json.encode(msg))
    assert schema_errors(payload, schema, schema) == []


@pytest.mark.parametrize(("msg_type", "payload", "invalid"), [c[1:] for c in BROKEN],
                         ids=[c[0] for c in BROKEN])
def test_schema_and_decoder_agree_on_broken_payloads(
    msg_type: type[m.Message], payload: dict[str, Any], invalid: bool
) -> None:
    schema = committed_schema(msg_type)
    errors = schema_errors(payload, schema, schema)
    accepted = decoder_accepts(msg_type, payload)
    assert accepted != invalid, f"the mutation itself is wrong: {payload!r:.300}"
    assert accepted == (not errors), (
        f"decoder {'accepts' if accepted else 'refuses'} {payload!r:.300} "
        f"but the committed schema says {errors or 'valid'}")


def test_enum_values_and_required_fields_match_the_types() -> None:
    for msg_type in m.ALL_MESSAGES:
        schema = committed_schema(msg_type)
        body = schema["$defs"][msg_type.__name__]
        info = msgspec.inspect.type_info(msg_type)
        assert isinstance(info, msgspec.inspect.StructType)
        fields = {f.encode_name: f for f in info.fields}
        where = f"schemas/messages/{msg_type.__name__}.json"
        assert set(body.get("properties", {})) == set(fields), where
        assert set(body.get("required", [])) == {n for n, f in fields.items() if f.required}, where
        assert body.get("additionalProperties") is False, where  # forbid_unknown_fields
        for name, field in fields.items():
            t = _unwrap(field.type)
            if isinstance(t, msgspec.inspect.EnumType | msgspec.inspect.LiteralType):
                values = ([v.value for v in t.cls] if isinstance(t, msgspec.inspect.EnumType)
                          else list(t.values))
                prop = body["properties"][name]
                if "anyOf" in prop:  # an optional enum: the branch that is not null
                    prop = next(p for p in prop["anyOf"] if p.get("type") != "null")
                enum = prop.get("enum")
                if enum is None:  # an enum type is referenced from $defs
                    ref = prop["$ref"].rsplit("/", 1)[-1]
                    enum = schema["$defs"][ref]["enum"]
                assert sorted(enum) == sorted(values), f"{where}: {name}"


def test_a_changed_struct_is_reported_as_drift(monkeypatch: pytest.MonkeyPatch) -> None:
    """The drift check above must notice a type change against the committed files:
    swap in a PupilControl with another range and one more field."""

    class PupilControl(m.Message):
        stamp_ns: m.StampNs
        dilation_percentage: m.Percent
        speed: float = 1.0

    changed = tuple(PupilControl if t is m.PupilControl else t for t in m.ALL_MESSAGES)
    monkeypatch.setattr(m, "ALL_MESSAGES", changed)
    assert schemas.drift(COMMITTED) == ["messages/PupilControl.json"]


def test_stale_and_unknown_files_are_reported(tmp_path: Path) -> None:
    schemas.write(tmp_path)
    target = tmp_path / "messages" / "PupilControl.json"
    target.write_text(target.read_text().replace("dilation_percentage", "dilation"))
    (tmp_path / "messages" / "Old.json").write_text("{}")
    (tmp_path / "keys.json").unlink()
    assert schemas.drift(tmp_path) == ["keys.json", "messages/Old.json",
                                       "messages/PupilControl.json"]


def test_committed_key_table_names_committed_schemas() -> None:
    """Every type the committed key table names has a committed schema, and every
    catalogue key is in it with its type (what a peer reads to subscribe)."""
    table = json.loads((COMMITTED / "keys.json").read_text())
    have = {p.stem for p in (COMMITTED / "messages").glob("*.json")}
    named = {row[f] for row in table for f in ("type", "request", "reply") if f in row}
    assert named and named <= have, named - have
    rows = {row["key"]: row for row in table}
    for topic in keys.TOPICS:
        assert rows[topic.pattern]["type"] == topic.type.__name__, topic.pattern
    for service in keys.SERVICES:
        row = rows[service.pattern]
        assert (row["request"], row["reply"]) == (service.request.__name__,
                                                  service.reply.__name__), service.pattern
