"""Find an app's class from FILE, MODULE or NAME (see `buddybot.runtime.appspec`).

Loading imports the app's code and nothing else happens: no connection, no
instance. Every way it can fail raises `AppError` (a `UsageError`: exit 2,
which `up` does not restart, since loading again would fail the same way)
with one line saying what was asked and what was found: no such file or
module, no app class, two candidates, a `run` that does not take
`(bot, stop_event)`, a class that cannot be made without arguments.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import inspect
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from buddybot.apps.app import App
from buddybot.runtime.appspec import AppSpec, node_name, parse_app_spec
from buddybot.runtime.errors import UsageError

GROUP = "buddybot.apps"
"""The entry-point group installed apps register under (`pyproject.toml`:
`[project.entry-points."buddybot.apps"] greeter = "mypkg.greeter:Greeter"`)."""


class AppError(UsageError):
    """The app cannot be loaded or run as given (exit 2)."""


@dataclass(frozen=True)
class LoadedApp:
    cls: type[Any]
    name: str
    """Its node name: the class's `name`, else the spec's default."""
    spec: AppSpec


def installed_apps() -> dict[str, str]:
    """Entry-point name -> `module:Class` of every installed app."""
    return {ep.name: ep.value for ep in importlib.metadata.entry_points(group=GROUP)}


def load_app(text: str) -> LoadedApp:
    """The app class `text` names, checked; AppError otherwise."""
    try:
        spec = parse_app_spec(text)
    except ValueError as exc:
        raise AppError(str(exc)) from None
    if spec.kind == "file":
        module = _import_file(Path(spec.target))
        where = spec.target
    elif spec.kind == "module":
        module = _import_module(spec.target)
        where = f"module {spec.target}"
    else:
        found = _entry_point(spec.target)
        if found is None:
            module = _import_module(spec.target, installed_too=True)
            where = f"module {spec.target}"
        else:
            loaded = _load_entry_point(found)
            if isinstance(loaded, type):
                check_app_class(loaded, f"installed app {spec.target!r} ({found.value})")
                return LoadedApp(loaded, _name_of(loaded, spec), spec)
            where = f"installed app {spec.target!r} ({found.value})"
            if not isinstance(loaded, ModuleType):
                raise AppError(f"{where}: names neither a class nor a module")
            module = loaded
    cls = pick_class(module, spec.cls, where)
    return LoadedApp(cls, _name_of(cls, spec), spec)


def _name_of(cls: type[Any], spec: AppSpec) -> str:
    own = getattr(cls, "name", None)
    return node_name(own) if isinstance(own, str) and own else spec.default_name


def pick_class(module: ModuleType, wanted: str | None, where: str) -> type[Any]:
    """The class `wanted` of `module`, or its one app class (defined in it, with `run`)."""
    if wanted is not None:
        cls = getattr(module, wanted, None)
        if not isinstance(cls, type):
            raise AppError(f"{where}: no class {wanted!r}")
        check_app_class(cls, f"{where}:{wanted}")
        return cls
    candidates = [obj for obj in vars(module).values()
                  if isinstance(obj, type) and obj.__module__ == module.__name__
                  and callable(getattr(obj, "run", None))]
    if not candidates:
        raise AppError(f"{where}: no app class (a class with run(self, bot, stop_event))")
    if len(candidates) > 1:
        names = ", ".join(sorted(c.__name__ for c in candidates))
        raise AppError(f"{where}: {len(candidates)} app classes ({names}); "
                       f"choose one with {where.removeprefix('module ')}:Class")
    check_app_class(candidates[0], f"{where}:{candidates[0].__name__}")
    return candidates[0]


def check_app_class(cls: type[Any], where: str) -> None:
    """`cls()` can be made and `run(bot, stop_event)` called, else AppError."""
    run = getattr(cls, "run", None)
    if not callable(run) or run is App.run:
        raise AppError(f"{where}: defines no run(self, bot, stop_event)")
    try:
        inspect.signature(run).bind(None, None, None)
    except TypeError:
        raise AppError(f"{where}: run{inspect.signature(run)} must take (self, bot, "
                       "stop_event)") from None
    except ValueError:  # no signature to read (a builtin): let the call decide
        pass
    try:
        inspect.signature(cls).bind()
    except TypeError:
        raise AppError(f"{where}: the class must be made without arguments, "
                       f"not {cls.__name__}{inspect.signature(cls)}") from None
    except ValueError:
        pass


def _import_file(path: Path) -> ModuleType:
    if not path.is_file():
        raise AppError(f"{path}: no such file")
    name = f"buddybot_app_{node_name(path.stem).replace('-', '_')}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise AppError(f"{path}: cannot be imported as Python")
    module = importlib.util.module_from_spec(spec)
    folder = str(path.resolve().parent)
    if folder not in sys.path:  # the app's own helper modules beside it
        sys.path.insert(0, folder)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        sys.modules.pop(name, None)
        raise _import_failed(str(path), exc) from None
    return module


def _import_module(name: str, installed_too: bool = False) -> ModuleType:
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and (name == exc.name or name.startswith(exc.name + ".")):
            also = (f" and no installed app of that name (installed: "
                    f"{', '.join(sorted(installed_apps())) or 'none'})") if installed_too else ""
            raise AppError(f"no module {name!r}{also}") from None
        raise _import_failed(f"module {name}", exc) from None
    except Exception as exc:
        raise _import_failed(f"module {name}", exc) from None


def _import_failed(where: str, exc: BaseException) -> AppError:
    """The app's own code failed while importing: its traceback, in the one line's place."""
    tb = exc.__traceback__
    while tb is not None and (tb.tb_frame.f_code.co_filename == __file__
                              or tb.tb_frame.f_code.co_filename.startswith("<frozen")
                              or "importlib" in tb.tb_frame.f_code.co_filename):
        tb = tb.tb_next  # the loader's own frames say nothing about the app
    lines = traceback.format_exception(type(exc), exc, tb)
    return AppError(f"{where}: failed to import:\n{''.join(lines).rstrip()}")


def _entry_point(name: str) -> importlib.metadata.EntryPoint | None:
    return next((ep for ep in importlib.metadata.entry_points(group=GROUP) if ep.name == name),
                None)


def _load_entry_point(ep: importlib.metadata.EntryPoint) -> Any:
    try:
        return ep.load()
    except Exception as exc:
        raise _import_failed(f"installed app {ep.name!r} ({ep.value})", exc) from None
