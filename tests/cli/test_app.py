"""`buddybot app run|new|list`: the template runs as generated against a real people
service and stops on SIGTERM; a bad app exits 2, a raising one 1 with its traceback,
one that ignores the stop is ended after the grace time."""

from __future__ import annotations

import json
import signal
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh

from buddybot import cli
from buddybot.cli.app import running_apps
from buddybot.runtime.node import Node
from buddybot.runtime.session import zenoh_config
from buddybot.tools.testing import Process, buddybot_argv
from tests.cli.process import bb
from tests.people.test_service import Visitor
from tests.sdk.conftest import start_people


def test_new_writes_an_app_and_refuses_to_overwrite_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["app", "new", "hello", "--dir", str(tmp_path)]) == 0
    assert f"wrote {tmp_path / 'hello.py'}" in capsys.readouterr().out
    assert "class Hello(App)" in (tmp_path / "hello.py").read_text()
    assert cli.main(["app", "new", "hello", "--dir", str(tmp_path)]) == 2
    assert "already exists: not overwritten" in capsys.readouterr().err
    assert cli.main(["app", "new", "9lives", "--dir", str(tmp_path)]) == 2
    assert cli.main(["app", "new", "x", "--dir", str(tmp_path / "nope")]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_running_apps_are_the_live_nodes_that_are_not_services() -> None:
    assert running_apps({"controller": set(), "greeter": set(), "people": set(),
                         "wizard_of_oz": set()}) == ["greeter", "wizard_of_oz"]


def app_file(folder: Path, name: str, code: str) -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(code))
    return path


def run_app(endpoint: str, log_dir: Path, *args: str) -> Process:
    return Process(buddybot_argv("app", "run", *args, "--connect", endpoint), "app", log_dir)


@pytest.mark.integration
def test_the_generated_app_runs_greets_and_stops_on_sigterm(
        spawn: Callable[..., Process], probe: Node, endpoint: str, log_dir: Path,
        tmp_path: Path) -> None:
    start_people(spawn, probe, tmp_path)
    assert bb("app", "new", "hello", "--dir", str(tmp_path)).returncode == 0
    app = run_app(endpoint, log_dir, str(tmp_path / "hello.py"))
    try:
        app.wait_for_output("hello: watching robot buddy; present now: []", 30)
        Visitor(probe).presence(True, 1.0)
        app.wait_for_output("hello: hello, person ", 30)
        start = time.monotonic()
        assert app.stop(timeout=10) == 0
        assert time.monotonic() - start < 5
    finally:
        app.stop()


@pytest.mark.integration
def test_bad_apps_exit_two_and_say_why(endpoint: str, tmp_path: Path) -> None:
    two = app_file(tmp_path, "two.py", """
        class A:
            def run(self, bot, stop_event): ...
        class B:
            def run(self, bot, stop_event): ...
        """)
    for spec, why in ((str(two), "2 app classes (A, B)"),
                      (str(tmp_path / "none.py"), "none.py: no such file"),
                      ("no_such_pkg.app", "no module 'no_such_pkg.app'")):
        result = bb("app", "run", spec, "--connect", endpoint)
        assert result.returncode == 2, result.stderr
        assert why in result.stderr and "Traceback" not in result.stderr


@pytest.mark.integration
def test_a_raising_app_exits_one_with_its_traceback(endpoint: str, tmp_path: Path) -> None:
    path = app_file(tmp_path, "boom.py", """
        class Boom:
            def run(self, bot, stop_event):
                raise RuntimeError("boom in the app")
        """)
    result = bb("app", "run", str(path), "--connect", endpoint)
    assert result.returncode == 1
    assert "Traceback" in result.stderr and "RuntimeError: boom in the app" in result.stderr


@pytest.mark.integration
def test_an_app_that_ignores_the_stop_is_ended_after_the_grace_time(
        endpoint: str, log_dir: Path, tmp_path: Path) -> None:
    path = app_file(tmp_path, "stubborn.py", """
        import time
        class Stubborn:
            def run(self, bot, stop_event):
                print("stubborn: running", flush=True)
                while True:
                    time.sleep(0.1)
        """)
    app = run_app(endpoint, log_dir, str(path), "--grace", "1")
    try:
        app.wait_for_output("stubborn: running", 30)
        start = time.monotonic()
        app.send_signal(signal.SIGTERM)
        assert app.proc.wait(15) == 0
        assert 0.9 < time.monotonic() - start < 10
        assert "did not return within 1 s of the stop" in app.output()
    finally:
        app.stop()


@pytest.mark.integration
def test_an_app_whose_threads_wait_inside_zenoh_at_its_stop_exits_cleanly(
        endpoint: str, log_dir: Path, tmp_path: Path) -> None:
    """Daemon threads blocked in a native Zenoh receive while samples pour in: at the
    end of an ordinary interpreter shutdown they are ended inside native code and
    glibc aborts the process (SIGABRT, "exception not rethrown"). The program exits
    without that shutdown, so the stop is a clean 0 every time."""
    path = app_file(tmp_path, "blocked.py", f"""
        import threading
        from buddybot.runtime.session import zenoh_config
        import zenoh
        class Blocked:
            def run(self, bot, stop_event):
                session = zenoh.open(zenoh_config(connect=[{endpoint!r}]))
                samples = session.declare_subscriber("flood/**")
                def read():
                    while True:
                        try:
                            samples.recv()
                        except Exception:
                            pass
                for _ in range(4):
                    threading.Thread(target=read, daemon=True).start()
                print("blocked: reading", flush=True)
                stop_event.wait()
                session.close()
        """)
    flooding = threading.Event()
    session = zenoh.open(zenoh_config(connect=[endpoint]))

    def flood() -> None:
        publisher = session.declare_publisher("flood/x")
        while not flooding.is_set():
            publisher.put(b"x" * 100)

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    statuses = []
    try:
        for run in range(3):
            app = run_app(endpoint, log_dir, str(path), "--name", f"blocked{run}")
            try:
                app.wait_for_output("blocked: reading", 30)
                statuses.append(app.stop(timeout=15))
            finally:
                app.stop()
    finally:
        flooding.set()
        flooder.join(10)
        session.close()
    assert statuses == [0, 0, 0], statuses


@pytest.mark.integration
def test_list_shows_installed_configured_and_running_apps(endpoint: str, log_dir: Path,
                                                          tmp_path: Path) -> None:
    config = tmp_path / "robot.toml"
    config.write_text('[apps]\nrun = ["examples/apps/greeter.py"]\n')
    result = bb("app", "list", "--json", "--connect", endpoint, "--config", str(config))
    assert result.returncode == 0, result.stderr
    listed = json.loads(result.stdout)
    assert listed["config"] == ["examples/apps/greeter.py"] and listed["running"] == []
    waiter = app_file(tmp_path, "waiter.py", """
        class Waiter:
            def run(self, bot, stop_event):
                print("waiter: up", flush=True)
                stop_event.wait()
        """)
    app = run_app(endpoint, log_dir, str(waiter))
    try:
        app.wait_for_output("waiter: up", 30)
        running = bb("app", "list", "--json", "--connect", endpoint)
        assert json.loads(running.stdout)["running"] == ["waiter"], running.stdout
    finally:
        app.stop()
    offline = bb("app", "list", "--connect", "tcp/127.0.0.1:1", "--timeout", "1")
    assert offline.returncode == 0 and "? (no router answered)" in offline.stdout
