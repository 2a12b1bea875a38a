"""The registry: every entry points at a real module, settings struct and doctor hooks."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.runtime import registry
from buddybot.runtime.health import DoctorHooks

ENTRIES = registry.SERVICES + registry.TOOLS


def test_names_modules_and_tables_are_unique() -> None:
    for field in ("name", "module"):
        values = [getattr(e, field) for e in ENTRIES]
        assert len(values) == len(set(values)), field
    tables = [e.table for e in registry.SERVICES]
    assert None not in tables and len(tables) == len(set(tables))


@pytest.mark.parametrize("entry", ENTRIES, ids=lambda e: e.name)
def test_every_entry_is_installed_and_loads(entry: registry.Entry) -> None:
    assert entry.exists()
    module = entry.load()
    assert callable(getattr(module, "add_arguments", None))


@pytest.mark.parametrize("entry", registry.SERVICES, ids=lambda e: e.name)
def test_every_service_has_a_settings_struct_with_defaults(entry: registry.Entry) -> None:
    kind = entry.settings_type()
    assert issubclass(kind, msgspec.Struct)
    kind()  # every field has a default: `buddybot up` runs without a config file
    assert callable(getattr(entry.load(), "run", None))


@pytest.mark.parametrize("entry", registry.SERVICES, ids=lambda e: e.name)
def test_doctor_hooks_are_doctor_hooks_or_none(entry: registry.Entry) -> None:
    hooks = entry.doctor_hooks()
    assert hooks is None if entry.doctor is None else isinstance(hooks, DoctorHooks)


def test_lookups() -> None:
    assert registry.service("controller") is not None
    assert registry.service("radar") is None  # a tool, not a service
    assert registry.service("nope") is None
    assert {e.name for e in registry.available_services()} == {e.name for e in registry.SERVICES}
    with pytest.raises(LookupError, match="radar has no config table"):
        registry.TOOLS[0].settings_type()


def test_a_missing_module_does_not_exist() -> None:
    ghost = registry.Entry("ghost", "buddybot.nowhere.ghost", "not installed")
    assert not ghost.exists()
