"""The machine's whole-robot slots: `robot` tests go to the slots' xdist groups in
turn, and a slot held by one test (of any run) keeps every other out until released."""

from __future__ import annotations

import fcntl
import os
from contextlib import ExitStack
from pathlib import Path

import pytest

from tests import robot_slots


@pytest.fixture(autouse=True)
def _own_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The slots of these tests are their own: a run of the suite beside holds the real ones."""
    monkeypatch.setattr(robot_slots, "FOLDER", tmp_path)


def _locked_elsewhere(slot: int) -> bool:
    fd = os.open(robot_slots.FOLDER / f"{slot}.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


class Item:
    """What `robot_slots` reads and writes of a pytest item: its markers."""

    def __init__(self, *marks: pytest.MarkDecorator) -> None:
        self.marks = [m.mark for m in marks]

    def get_closest_marker(self, name: str) -> pytest.Mark | None:
        return next((m for m in self.marks if m.name == name), None)

    def iter_markers(self, name: str) -> list[pytest.Mark]:
        return [m for m in self.marks if m.name == name]

    def add_marker(self, marker: pytest.MarkDecorator) -> None:
        self.marks.append(marker.mark)


def test_robot_tests_are_dealt_to_the_slots_in_turn() -> None:
    items = [Item(pytest.mark.robot), Item(), Item(pytest.mark.robot), Item(pytest.mark.robot)]
    robot_slots.assign(items)  # type: ignore[arg-type]
    assert [robot_slots.slot_of(i) for i in items] == [0, None, 1, 0]  # type: ignore[arg-type]
    assert items[2].iter_markers("xdist_group")[0].args == ("robot-1",)


def test_a_held_slot_keeps_others_out_until_released() -> None:
    with robot_slots.held(1):
        assert _locked_elsewhere(1)
        assert not _locked_elsewhere(0)
    assert not _locked_elsewhere(1)


def test_heavy_slots_are_taken_one_each_and_a_full_machine_makes_the_next_wait() -> None:
    with ExitStack() as stack:
        for _ in range(robot_slots.HEAVY):
            stack.enter_context(robot_slots.any_heavy(wait_s=0.0))
        with pytest.raises(TimeoutError, match="no heavy-test slot"), \
                robot_slots.any_heavy(wait_s=0.3):
            pass
    with robot_slots.any_heavy(wait_s=0.0):
        pass  # freed again


def test_only_tests_with_processes_or_a_browser_are_heavy() -> None:
    assert robot_slots.heavy(Item(pytest.mark.integration))  # type: ignore[arg-type]
    assert robot_slots.heavy(Item(pytest.mark.browser))  # type: ignore[arg-type]
    assert not robot_slots.heavy(Item(pytest.mark.model))  # type: ignore[arg-type]
