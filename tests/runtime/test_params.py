"""Live parameters: the live marks, validation, the holder, the CLI helpers, and (through a
real router) a running service answering `params/<node>` with a valid message (the `param`
verb's tests are tests/cli/test_param.py)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.settings import RadarPresenceSettings
from buddybot.runtime import registry
from buddybot.runtime.node import Node
from buddybot.runtime.params import LiveSettings, ParamRefused, describe, is_live, validate
from buddybot.tools.testing import Process
from tests.cli.process import wait_params

Spawn = Callable[..., Process]


class Tuning(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    gain: Annotated[float, msgspec.Meta(ge=0.0, le=2.0, extra={"live": True},
                                        description="how loud")] = 1.0
    name: Annotated[str | None, msgspec.Meta(extra={"live": True})] = None
    port: Annotated[int, msgspec.Meta(ge=1, le=65535)] = 80
    low: Annotated[float, msgspec.Meta(extra={"live": True})] = 0.0
    high: Annotated[float, msgspec.Meta(extra={"live": True})] = 1.0

    def __post_init__(self) -> None:
        if self.low > self.high:
            raise ValueError("low must not exceed high")


def test_live_marks_come_from_the_field_meta() -> None:
    assert is_live(Tuning, "gain") and is_live(Tuning, "name")
    assert not is_live(Tuning, "port")
    assert is_live(RadarPresenceSettings, "range_m")
    assert not is_live(RadarPresenceSettings, "max_sensors")
    with pytest.raises(KeyError):
        is_live(Tuning, "nope")


def test_required_live_fields_are_marked() -> None:
    """The fields the issue names as live are live; ports, devices, models are not."""
    from buddybot.audio.settings import AudioPlayerSettings
    from buddybot.camera.settings import FaceDetectorSettings
    from buddybot.controller.settings import ControllerSettings
    from buddybot.eyes.settings import EyesSettings

    live = {
        RadarPresenceSettings: ["range_m", "exit_margin_m", "absence_hold_s", "target_hold_s",
                                "moving_speed_mps", "zones"],
        ControllerSettings: ["greet_dwell_s", "regreet_cooldown_s", "farewell_delay_s"],
        EyesSettings: ["pupil_curve", "lids", "unknown_distance_percent"],
        AudioPlayerSettings: ["volume"],
        FaceDetectorSettings: ["min_score", "smoothing", "full_every_s", "face_width_m"],
    }
    restart = {
        RadarPresenceSettings: ["max_sensors"],
        ControllerSettings: ["camera", "tick_s"],
        AudioPlayerSettings: ["device", "backend", "sample_rate"],
        FaceDetectorSettings: ["camera", "model", "model_path", "threads"],
    }
    for struct, names in live.items():
        for name in names:
            assert is_live(struct, name), f"{struct.__name__}.{name}"
    for struct, names in restart.items():
        for name in names:
            assert not is_live(struct, name), f"{struct.__name__}.{name}"


def test_every_registered_table_describes_without_error() -> None:
    for entry in registry.SERVICES:
        kind = entry.settings_type()
        rows = describe(kind())
        assert [r.name for r in rows] == list(kind.__struct_fields__)
        for row in rows:  # a reply must encode
            msgspec.json.encode(row)


def test_describe_gives_value_type_range_and_mark() -> None:
    rows = {r.name: r for r in describe(Tuning(gain=1.5))}
    assert rows["gain"].value == 1.5 and rows["gain"].type == "float"
    assert rows["gain"].range == "0..2" and rows["gain"].live
    assert rows["gain"].description == "how loud"
    assert rows["port"].range == "1..65535" and not rows["port"].live


def test_validate_applies_a_live_change_and_converts_types() -> None:
    new, changed = validate(Tuning(), {"gain": 2, "name": "x"})
    assert new.gain == 2.0 and isinstance(new.gain, float) and new.name == "x"
    assert changed == ["gain", "name"]


def test_out_of_range_is_refused_naming_field_and_range() -> None:
    with pytest.raises(ParamRefused, match=r"gain = 3 refused: allowed 0\.\.2") as exc:
        validate(Tuning(), {"gain": 3})
    assert not exc.value.unknown


def test_wrong_type_is_refused() -> None:
    with pytest.raises(ParamRefused, match=r"gain = 'loud' refused: Expected `float`, got `str`"):
        validate(Tuning(), {"gain": "loud"})


def test_a_bad_item_of_a_list_is_refused_saying_which_and_why() -> None:
    """Not the list's own bound ("at most 16 items"), which the value keeps."""
    from buddybot.radar.settings import RadarPresenceSettings

    zone = {"name": "tv", "mode": "ignore", "x": [1.0, 2.0], "y": [0.0, 1.0]}
    with pytest.raises(ParamRefused, match=r"refused: Expected `float` <= 20.0 - at "
                                           r"`zones\[1\].y\[1\]`"):
        validate(RadarPresenceSettings(), {"zones": [zone, {**zone, "y": [0.0, 100.0]}]})


def test_restart_field_is_refused_unless_unchanged() -> None:
    with pytest.raises(ParamRefused, match="port needs a restart"):
        validate(Tuning(), {"port": 81})
    new, changed = validate(Tuning(), {"port": 80, "gain": 0.5})  # a dump loads back
    assert changed == ["gain"] and new.port == 80


def test_unknown_field_is_a_usage_refusal() -> None:
    with pytest.raises(ParamRefused, match="no parameter 'gian'") as exc:
        validate(Tuning(), {"gian": 1})
    assert exc.value.unknown


def test_cross_field_checks_run() -> None:
    with pytest.raises(ParamRefused, match="low must not exceed high"):
        validate(Tuning(), {"low": 2.0})


def test_holder_calls_apply_and_keeps_the_old_struct_on_refusal() -> None:
    seen: list[Tuning] = []
    holder = LiveSettings(Tuning(), seen.append)
    assert holder.set({"gain": 0.5}) == ["gain"]
    assert seen[-1].gain == 0.5 and holder.current.gain == 0.5
    assert holder.changes == 1 and holder.last_change == "gain=0.5"
    with pytest.raises(ParamRefused):
        holder.set({"gain": 0.1, "port": 1})  # all or nothing
    assert holder.current.gain == 0.5 and len(seen) == 1
    assert holder.set({"gain": 0.5}) == []  # unchanged: apply not called
    assert len(seen) == 1


def test_holder_refuses_what_the_service_refuses() -> None:
    def apply(_new: Tuning) -> None:
        raise RuntimeError("device busy")

    holder = LiveSettings(Tuning(), apply)
    with pytest.raises(ParamRefused, match="device busy"):
        holder.set({"gain": 0.2})
    assert holder.current.gain == 1.0


def test_handle_answers_list_get_set_and_errors() -> None:
    holder = LiveSettings(Tuning())
    listed = holder.handle("n", m.ParamRequest(op="list"))
    assert [p.name for p in listed.params] == list(Tuning.__struct_fields__)
    got = holder.handle("n", m.ParamRequest(op="get", name="gain"))
    assert got.params[0].value == 1.0 and not got.error
    bad = holder.handle("n", m.ParamRequest(op="get", name="nope"))
    assert bad.unknown and "nope" in bad.error
    refused = holder.handle("n", m.ParamRequest(op="set", values={"gain": 9}))
    assert "allowed 0..2" in refused.error and not refused.unknown
    ok = holder.handle("n", m.ParamRequest(op="set", values={"gain": 0.25}))
    assert ok.changed == ["gain"] and ok.params[0].value == 0.25


@pytest.mark.integration
def test_a_reply_is_a_valid_message(spawn: Spawn, endpoint: str, probe: Node) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    reply = probe.call(keys.PARAMS, m.ParamRequest(op="get", name="range_m"),
                       node="radar-presence")
    assert isinstance(reply, m.ParamReply) and reply.params[0].value == 2.0
