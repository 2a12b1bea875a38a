"""Eye styles: every expression as a key pose of a few shape parameters (pure).

The page (web/eyes.js) draws an eye from a handful of numbers (size,
corner roundness, lids, glow, colour, shape) and interpolates every one of
them with easing when the expression changes, so a new expression is a
new set of numbers, not new drawing code. Those numbers are data: the
built-in styles ship as `styles.json` next to this module, and a user file
(`[eye_renderer] style_file`) adds styles or changes built-in ones without
touching code.

File format (docs/eyes.md has an example)::

    {"styles": {"NAME": {"extends": "glow", "color": "#ff8000",
                         "base": {POSE}, "poses": {"GRIN": {POSE}, ...}}}}

A pose lists only what differs: a style's `base` fills every field a pose
leaves out, and `extends` (or, for a user style named like a built-in one,
that built-in style itself) fills whatever the style leaves out, field by
field and pose by pose. After that every style must be complete: a kind,
every style field and every pose field, for all nine expressions.

Every value is checked (type, range, unknown keys); a bad one is a
`ConfigError` (exit status 2) naming the file and the key path, e.g.
`styles.glow.poses.GRIN.top_lid: expected <= 100`. No I/O but `load_file`
and `builtin` (which read one file each).
"""

from __future__ import annotations

import importlib.resources
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec

from buddybot.runtime import nesting
from buddybot.runtime.errors import ConfigError

MAX_FILE_BYTES = 256 * 1024
"""The largest style file read (the built-in one is 2.5 kB): a file of
200,000 styles would take the renderer to gigabytes."""
MAX_STYLES = 256
"""Styles one file may define."""
MAX_EXTENDS = 16
"""Styles one `extends` chain may pass through."""
EXPRESSIONS = ("AWAKE", "SLEEP", "SLEEPY", "GRIN", "SAD", "LOOK_RANDOM", "LOVE", "STAR",
               "ALERT")
"""Pose names, in `ExpressionAction` order (contract/messages.py without the EYE_/ANIMATE_
prefixes, as the page's EXPR table names them)."""

Percent = Annotated[float, msgspec.Meta(ge=0.0, le=100.0)]
Colour = Annotated[str, msgspec.Meta(pattern=r"^#[0-9a-fA-F]{6}$")]
PoseColour = Annotated[str, msgspec.Meta(pattern=r"^(#[0-9a-fA-F]{6})?$")]
Angle = Annotated[float, msgspec.Meta(ge=-45.0, le=45.0)]
Spin = Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]
Shape = Literal["eye", "heart", "star"]
Kind = Literal["glow", "eyeball"]
"""How the page draws a style: `glow`, a glowing rounded shape whose lids cut it
(the look of FluxGarage RoboEyes or Anki Vector), or `eyeball`, a white ball
with iris, pupil and catch-light."""


class Pose(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """One eye's shape: sizes are % of the eye's cell (the smaller side of the
    screen area one eye gets), lids are % of the eye's height, so a pose looks
    the same on any screen."""

    width: Percent
    height: Percent
    roundness: Percent
    """Corner radius, % of half the shorter side (100: a pill or a circle)."""
    top_lid: Percent
    """The least the top lid covers; the commanded lids (`eyes/lids`) may cover more."""
    top_lid_angle: Angle
    """Degrees; > 0 lowers the outer corner (sad, drowsy), < 0 the inner one (cross)."""
    bottom_lid: Percent
    bottom_lid_curve: Percent
    """0: a straight bottom lid; 100: it arches up into a happy crescent."""
    iris: Percent
    """Iris diameter, % of the eye's width (glow: the bright core around the pupil;
    0: none, and no pupil)."""
    pupil: Percent
    """Pupil size, % of what the commanded dilation asks for."""
    glow: Percent
    brightness: Percent
    breathe: Percent
    """Brightness swing of a slow (~0.25 Hz) breath, % (asleep, drowsy)."""
    sway: Percent = 0.0
    """How far the top lid sinks with each slow breath and lifts again, % of the
    eye's height (drowsy)."""
    beat: Percent
    """Size swing of a heartbeat, % (love)."""
    spin: Spin
    """Degrees per second the shape turns (stars)."""
    color: PoseColour
    """The eye's (glow) or iris's (eyeball) colour; empty: the style's colour."""
    shape: Shape
    transition_ms: Annotated[float, msgspec.Meta(ge=0.0, le=5000.0)] = 0.0
    """How long a change into this pose takes (falling asleep is slow); 0: the
    style's `transition_ms`."""


POSE_REQUIRED = tuple(f.name for f in msgspec.structs.fields(Pose) if f.required)
"""Pose fields a complete style must give (the others have defaults, so a style
file written before they existed still loads)."""


class PoseSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, omit_defaults=True):
    """A pose as written in a file: any field may be left out (inherited)."""

    width: Percent | None = None
    height: Percent | None = None
    roundness: Percent | None = None
    top_lid: Percent | None = None
    top_lid_angle: Angle | None = None
    bottom_lid: Percent | None = None
    bottom_lid_curve: Percent | None = None
    iris: Percent | None = None
    pupil: Percent | None = None
    glow: Percent | None = None
    brightness: Percent | None = None
    breathe: Percent | None = None
    sway: Percent | None = None
    beat: Percent | None = None
    spin: Spin | None = None
    color: PoseColour | None = None
    shape: Shape | None = None
    transition_ms: Annotated[float, msgspec.Meta(ge=0.0, le=5000.0)] | None = None


class Style(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A complete style as the page gets it: every expression's resolved pose."""

    name: str
    kind: Kind
    description: str
    background: Colour
    """Background and lid colour (the eyes are cut-outs)."""
    color: Colour
    lid_follow: Percent
    """How far the lids follow the gaze up and down, % of the eye's height at the
    largest pitch (people's lids do: looking up raises the top lid)."""
    curiosity: Percent
    """% the eye on the side looked at grows at the largest yaw (the other shrinks
    by half as much)."""
    vergence: Percent
    """% of the eye's cell each eye moves toward the nose for a person at 30 cm
    (none beyond 150 cm)."""
    squash: Percent
    """% of a blink done by flattening the eye, the rest by its lids closing (squash
    and stretch: a glow eye gets flatter as it shuts, its corners staying round)."""
    stretch: Percent
    """% wider a fully closed eye is."""
    reach: Percent
    """How far the eye (glow) or iris (eyeball) moves at the largest yaw or pitch,
    % of the eye's cell."""
    transition_ms: Annotated[float, msgspec.Meta(ge=0.0, le=5000.0)]
    """How long a change of expression takes (eased in and out)."""
    poses: dict[str, Pose]


class StyleSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, omit_defaults=True):
    """A style as written in a file (`base` and `poses` are checked on their own,
    so an error names the pose)."""

    extends: str | None = None
    kind: Kind | None = None
    description: str | None = None
    background: Colour | None = None
    color: Colour | None = None
    lid_follow: Percent | None = None
    curiosity: Percent | None = None
    vergence: Percent | None = None
    squash: Percent | None = None
    stretch: Percent | None = None
    reach: Percent | None = None
    transition_ms: Annotated[float, msgspec.Meta(ge=0.0, le=5000.0)] | None = None
    base: dict[str, Any] | None = None
    poses: dict[str, Any] | None = None


STYLE_FIELDS = tuple(f for f in Style.__struct_fields__ if f not in ("name", "poses"))


# --- errors that name the key ---------------------------------------------------------

_AT = re.compile(r"^(?P<what>.*?)(?: - at `(?P<path>[^`]*)`)?$", re.S)
_BOUND = re.compile(r"Expected `(?:float|int)(?: \| null)?` (?P<op>[<>]=?) (?P<num>[-0-9.e+]+)")


def _num(text: str) -> str:
    value = float(text)
    return str(int(value)) if value.is_integer() else repr(value)


def _readable(exc: msgspec.ValidationError, where: str) -> str:
    """msgspec's "Expected `float` <= 100.0 - at `$.top_lid`" as
    "where.top_lid: expected <= 100"."""
    found = _AT.match(str(exc))
    what, path = (found.group("what"), found.group("path") or "$") if found else (str(exc), "$")
    bound = _BOUND.match(what)
    if bound:
        what = f"expected {bound.group('op')} {_num(bound.group('num'))}"
    else:
        what = what.replace(" | null", "")
        what = what[:1].lower() + what[1:]
    key = path.replace("key` in `", "").lstrip("$")
    return f"{where}{key}: {what}"


def _convert(data: Any, kind: type[Any], where: str, source: str) -> Any:
    try:
        return msgspec.convert(data, kind)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{source}: {_readable(exc, where)}") from None


# --- loading --------------------------------------------------------------------------


def _pose_spec(data: Any, where: str, source: str) -> dict[str, Any]:
    """One pose's given fields (validated), as a dict."""
    spec = _convert(data, PoseSpec, where, source)
    return {k: v for k, v in msgspec.structs.asdict(spec).items() if v is not None}


def parse(data: Any, source: str) -> dict[str, dict[str, Any]]:
    """A decoded style file -> {style name: its given fields} (nothing inherited
    yet); every value, pose name and key checked, errors naming the key path."""
    if not isinstance(data, dict) or set(data) != {"styles"}:
        raise ConfigError(f"{source}: a style file is an object with one key, \"styles\"")
    styles = data["styles"]
    if not isinstance(styles, dict):
        raise ConfigError(f"{source}: styles: expected an object of styles by name")
    if len(styles) > MAX_STYLES:
        raise ConfigError(f"{source}: styles: {len(styles)} styles, at most {MAX_STYLES}")
    out: dict[str, dict[str, Any]] = {}
    for name, raw in styles.items():
        where = f"styles.{name}"
        if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", name):
            raise ConfigError(f"{source}: {where}: a style name is 1-64 letters, digits, "
                              "_ or -")
        spec = _convert(raw, StyleSpec, where, source)
        fields = {k: v for k, v in msgspec.structs.asdict(spec).items()
                  if v is not None and k not in ("base", "poses")}
        fields["base"] = _pose_spec(spec.base or {}, f"{where}.base", source)
        poses: dict[str, dict[str, Any]] = {}
        for expr, pose in (spec.poses or {}).items():
            if expr not in EXPRESSIONS:
                raise ConfigError(f"{source}: {where}.poses.{expr}: unknown expression "
                                  f"(known: {', '.join(EXPRESSIONS)})")
            poses[expr] = _pose_spec(pose, f"{where}.poses.{expr}", source)
        fields["poses"] = poses
        out[name] = fields
    return out


def _layer(under: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """`over`'s given fields on top of `under`'s. Poses: `under`'s own (its base
    under its pose), then `over`'s base, then `over`'s pose, field by field, so
    a child's base changes every inherited pose and its poses change one."""
    merged = {**under, **{k: v for k, v in over.items() if k not in ("base", "poses")}}
    under_base, under_poses = under.get("base", {}), under.get("poses", {})
    over_base, over_poses = over.get("base", {}), over.get("poses", {})
    merged["base"] = {}
    merged["poses"] = {e: {**under_base, **under_poses.get(e, {}), **over_base,
                           **over_poses.get(e, {})} for e in EXPRESSIONS}
    merged.pop("extends", None)
    return merged


class StyleLibrary:
    """Every known style, complete (resolved at load: errors come at start)."""

    def __init__(self, styles: Mapping[str, Style]) -> None:
        self.styles = dict(styles)

    @property
    def names(self) -> list[str]:
        return sorted(self.styles)

    def get(self, name: str, key: str = "eye_renderer.style") -> Style:
        """The style `name`; a ConfigError naming `key` and the known styles if none."""
        style = self.styles.get(name)
        if style is None:
            raise ConfigError(f"{key} = {name!r}: no such style (known: "
                              f"{', '.join(self.names)})")
        return style


def resolve(specs: Mapping[str, Mapping[str, Any]], source: str,
            known: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, Style]:
    """Complete styles from given fields: `extends` chains followed, a style
    named like one in `known` layered over it, then every field required."""
    known = dict(known or {})
    done: dict[str, dict[str, Any]] = {}

    def flat(name: str) -> dict[str, Any]:
        """Follow `extends` up (a loop, not recursion: the chain is the file's
        to choose), then layer from the top down."""
        chain: list[str] = []
        current = name
        under: dict[str, Any] | None = None
        while current not in done:
            if current in chain:
                raise ConfigError(f"{source}: styles.{current}.extends: a loop "
                                  f"({' -> '.join([*chain[chain.index(current):], current])})")
            if len(chain) >= MAX_EXTENDS:
                raise ConfigError(f"{source}: styles.{name}.extends: a chain longer than "
                                  f"{MAX_EXTENDS} styles")
            chain.append(current)
            parent = specs[current].get("extends")
            if parent is None:
                under = dict(known.get(current, {}))
                break
            if parent in specs and parent != current:
                current = parent
                continue
            if parent in known:
                under = dict(known[parent])
                break
            raise ConfigError(f"{source}: styles.{current}.extends = {parent!r}: no such "
                              f"style (known: {', '.join(sorted({*specs, *known}))})")
        if under is None:
            under = done[current]
        for step in reversed(chain):
            under = done[step] = _layer(under, specs[step])
        return done[name]

    result: dict[str, Style] = {}
    for name in specs:
        fields = flat(name)
        missing = [f for f in STYLE_FIELDS if f not in fields]
        if missing:
            raise ConfigError(f"{source}: styles.{name}: missing {', '.join(missing)} "
                              "(or give \"extends\")")
        poses = {}
        for expr in EXPRESSIONS:
            pose = {**fields["base"], **fields["poses"].get(expr, {})}
            missing = [f for f in POSE_REQUIRED if f not in pose]
            if missing:
                raise ConfigError(f"{source}: styles.{name}.poses.{expr}: missing "
                                  f"{', '.join(missing)} (give them in its base)")
            poses[expr] = _convert(pose, Pose, f"styles.{name}.poses.{expr}", source)
        style_fields = {k: fields[k] for k in STYLE_FIELDS}
        result[name] = _convert({**style_fields, "name": name, "poses": {}}, Style,
                                f"styles.{name}", source)
        result[name].poses = poses
    return result


def _decode(text: bytes, source: str) -> Any:
    try:
        nesting.check_depth(text)
        return msgspec.json.decode(text)
    except (msgspec.DecodeError, nesting.TooDeep) as exc:
        raise ConfigError(f"{source}: not valid JSON: {exc}") from None


def builtin_specs() -> dict[str, dict[str, Any]]:
    """The built-in styles' given fields (the package's styles.json)."""
    text = (importlib.resources.files("buddybot.eyes") / "styles.json").read_bytes()
    return parse(_decode(text, "styles.json"), "styles.json")


def load(style_file: Path | None = None) -> StyleLibrary:
    """The built-in styles plus, with `style_file`, the user's on top of them."""
    base = builtin_specs()
    styles = resolve(base, "styles.json")
    if style_file is None:
        return StyleLibrary(styles)
    source = str(style_file)
    try:
        with open(style_file, "rb") as stream:
            text = stream.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read style file: {exc.strerror or exc}") from None
    if len(text) > MAX_FILE_BYTES:
        raise ConfigError(f"{source}: a style file is at most {MAX_FILE_BYTES // 1024} kB: "
                          "not read")
    user = parse(_decode(text, source), source)
    known = {name: _known(style) for name, style in styles.items()}
    styles.update(resolve(user, source, known))
    return StyleLibrary(styles)


def _known(style: Style) -> dict[str, Any]:
    """A complete style as given fields (what a user style layers over)."""
    fields = {k: getattr(style, k) for k in STYLE_FIELDS}
    fields["base"] = {}
    fields["poses"] = {e: msgspec.structs.asdict(p) for e, p in style.poses.items()}
    return fields
