"""The checked-in `buddybot_interfaces` package is exactly what the contract generates."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Annotated

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.ros2 import interfaces


def test_the_checked_in_package_equals_the_generated_one() -> None:
    assert interfaces.drift() == [], "run: python -m buddybot.ros2.interfaces"


def test_drift_names_a_stale_a_missing_and_an_extra_file(tmp_path: Path) -> None:
    out = tmp_path / "pkg"
    shutil.copytree(interfaces.ROOT, out)
    (out / "msg" / "EyeControl.msg").write_text("float32 yaw\n")
    (out / "msg" / "PupilControl.msg").unlink()
    (out / "msg" / "Old.msg").write_text("int8 x\n")
    assert interfaces.drift(out) == ["msg/EyeControl.msg", "msg/Old.msg", "msg/PupilControl.msg"]
    assert interfaces.main(["--check", str(out)]) == 1
    assert interfaces.main([str(out)]) == 0
    (out / "msg" / "Old.msg").unlink()
    assert interfaces.main(["--check", str(out)]) == 0


def test_every_file_is_listed_in_cmakelists() -> None:
    files = interfaces.generate()
    cmake = files["CMakeLists.txt"]
    for name in files:
        if name.endswith((".msg", ".srv", ".action")):
            assert f'"{name}"' in cmake


def test_the_seed_field_names_and_units_are_kept() -> None:
    files = interfaces.generate()
    lids = files["msg/EyeLidControl.msg"]
    assert "uint8 eye_id" in lids and "float64 top_lid_position" in lids
    assert "uint8 BOTH=2" in lids
    assert "uint8 action" in files["msg/ScreenExpression.msg"]
    assert "uint8 EYE_GRIN=3" in files["msg/ScreenExpression.msg"]
    frame = files["msg/LD2410TargetDataFrame.msg"]
    assert "uint16 movement_distance  # >= 0, <= 65535; cm, 16-bit" in frame
    assert "uint8 movement_energy" in frame
    assert "LD2410TargetDataFrame[] sensors" in files["msg/LD2410TargetDataFrameArray.msg"]
    assert "float64 dilation_percentage" in files["msg/PupilControl.msg"]
    goal, result, feedback = files["action/PlaySound.action"].split("\n---\n")
    assert "string<=256 sound" in goal
    assert "string state" in result and "float64 progress" in feedback


@pytest.mark.parametrize(("annotation", "ros_type"), [
    (Annotated[int, msgspec.Meta(ge=0, le=255)], "uint8"),
    (Annotated[int, msgspec.Meta(ge=0, le=256)], "uint16"),
    (Annotated[int, msgspec.Meta(ge=0, lt=65536)], "uint16"),
    (Annotated[int, msgspec.Meta(ge=0)], "uint64"),
    (Annotated[int, msgspec.Meta(ge=-128, le=127)], "int8"),
    (int, "int64"),
    (float, "float64"),
    (bool, "bool"),
    (bytes, "uint8[]"),
    (Annotated[str, msgspec.Meta(max_length=8)], "string<=8"),
    (Annotated[list[int], msgspec.Meta(max_length=3)], "int64[<=3]"),
    (Annotated[int, msgspec.Meta(ge=0, le=8)] | None, "uint8[<=1]"),
    (list[float] | None, "float64[]"),
    (m.ExpressionAction, "uint8"),
    (m.Point, "Point"),
])
def test_field_types(annotation: object, ros_type: str) -> None:
    probe = msgspec.defstruct("Probe", [("value", annotation)], bases=(m.Message,))
    info = msgspec.inspect.type_info(probe)
    assert isinstance(info, msgspec.inspect.StructType)
    assert interfaces.ros_field(info.fields[0].type, "Probe.value").ros_type == ros_type


def test_a_field_without_a_ros_type_is_an_error() -> None:
    class Probe(m.Message):
        values: dict[str, int]

    with pytest.raises(interfaces.InterfaceError, match=r"Probe\.values"):
        interfaces.section(interfaces.Part(Probe))


def test_clashing_enum_constants_are_an_error() -> None:
    class Probe(m.Message):
        first: m.PresenceTarget
        second: m.PresenceTarget

    with pytest.raises(interfaces.InterfaceError, match="MOVING"):
        interfaces.section(interfaces.Part(Probe))


def test_a_part_naming_a_missing_field_is_an_error() -> None:
    with pytest.raises(interfaces.InterfaceError, match="nonsense"):
        interfaces.section(interfaces.Part(m.PlaySoundStatus, ("nonsense",)))
