"""`buddybot up` cannot be fooled: a busy router port, a service that
exits 2, a typo in `--only`, joining a router with `--connect`, the port options.

Real processes on a real loopback router; the option rules themselves (which
services, which arguments) are checked without processes.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from buddybot.runtime import registry
from buddybot.runtime.config import default_config, parse_config
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node, zenoh_config
from buddybot.runtime.service import ServiceContext
from buddybot.supervisor.launch import (
    AppLaunch,
    app_argv,
    plan_apps,
    plan_up,
    select_services,
    service_argv,
)
from buddybot.supervisor.status import RobotStatus, format_status
from buddybot.tools.testing import (
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
)

REPO = Path(__file__).resolve().parents[2]

# --- the option rules, no processes ----------------------------------------------------


def _ctx(**options: object) -> ServiceContext:
    args = argparse.Namespace(sim=True, no_browser=True, listen=None, only=None, eye_port=None,
                              dashboard_port=None, status_period=5.0, config=None,
                              connect=None, robot=None, log_level="INFO")
    for key, value in options.items():
        setattr(args, key, value)
    return ServiceContext(name="up", args=args, config=default_config(), robot="buddy",
                          connect=["tcp/127.0.0.1:7447"])


def test_only_with_an_unknown_name_names_it_and_the_valid_ones() -> None:
    with pytest.raises(UsageError) as caught:
        select_services(["camera", "camra"], list(registry.SERVICES),
                        registry.available_services())
    text = str(caught.value)
    assert "'camra'" in text and "'camera'" not in text
    assert all(e.name in text for e in registry.SERVICES)


def test_only_selects_in_registry_order() -> None:
    chosen = select_services(["controller", "camera"], list(registry.SERVICES),
                             registry.available_services())
    assert [e.name for e in chosen] == ["camera", "controller"]


def test_eye_port_goes_to_the_eye_renderer_and_the_dashboard_frame() -> None:
    plan = plan_up(_ctx(eye_port=18080, dashboard_port=18090))
    assert plan.service_args["eye-renderer"] == ["--port", "18080"]
    assert plan.service_args["dashboard"] == ["--eye-port", "18080", "--port", "18090"]
    assert set(plan.service_args) == {"eye-renderer", "dashboard", *WORLD_USERS}
    argv = service_argv("eye-renderer", _ctx(), plan.connect,
                        plan.service_args["eye-renderer"])
    assert argv[-2:] == ["--port", "18080"] and "--no-browser" in argv


WORLD_USERS = {"radar-bridge", "camera", "sim"}
"""The simulated sensors and the service publishing the world's truth."""


def test_every_simulated_sensor_gets_the_same_world_and_start() -> None:
    plan = plan_up(_ctx(scenario="two_people", seed=7))
    assert {e.name for e in plan.entries} >= WORLD_USERS
    worlds = {tuple(plan.service_args[name]) for name in WORLD_USERS}
    assert len(worlds) == 1
    (world,) = worlds
    assert world[:2] == ("--scenario", "two_people") and world[-2:] == ("--seed", "7")
    start = float(world[world.index("--sim-start") + 1])
    assert time.time() < start < time.time() + 10  # a moment from now: sensors are starting
    argv = service_argv("camera", _ctx(), plan.connect, plan.service_args["camera"])
    assert "--sim" in argv and "two_people" in argv


def test_a_robot_with_its_hardware_has_no_simulated_world() -> None:
    config = parse_config("[radar_bridge]\nsensors = ['/dev/ttyUSB0']\n"
                          "[camera]\nsource = '0'\n")
    ctx = _ctx(sim=False)
    ctx.config = config
    plan = plan_up(ctx)
    assert "sim" not in {e.name for e in plan.entries}
    assert not set(plan.service_args) & WORLD_USERS
    assert "--sim" not in service_argv("radar-bridge", ctx, plan.connect)


def test_a_bad_scenario_stops_up_before_anything_starts(tmp_path: Path) -> None:
    bad = tmp_path / "party.toml"
    bad.write_text('description = "x"\nlength_s = 5\n[[person]]\nface = "nobody"\n'
                   'path = [{ t = 0, x = 1, y = 0 }]\n')
    with pytest.raises(UsageError, match=r"party.toml, line 4, key 'person\[0\].face'"):
        plan_up(_ctx(scenario=str(bad)))
    with pytest.raises(UsageError, match="no such scenario"):
        plan_up(_ctx(scenario="party"))


def test_on_request_services_start_only_when_asked() -> None:
    """The Foxglove bridge is not part of a plain `up`; `--foxglove` or `--only` adds it."""
    assert "foxglove" not in {e.name for e in plan_up(_ctx()).entries}
    assert "dashboard" in {e.name for e in plan_up(_ctx()).entries}
    assert "foxglove" in {e.name for e in plan_up(_ctx(foxglove=True)).entries}
    assert [e.name for e in plan_up(_ctx(only=["foxglove"])).entries] == ["foxglove"]
    assert [e.name for e in plan_up(_ctx(only=["camera"], foxglove=True)).entries] == [
        "camera", "foxglove"]


def test_the_ros2_bridge_starts_with_up_ros2_or_its_enabled_switch() -> None:
    assert "ros2-bridge" not in {e.name for e in plan_up(_ctx()).entries}
    assert "ros2-bridge" in {e.name for e in plan_up(_ctx(ros2=True)).entries}
    assert [e.name for e in plan_up(_ctx(only=["camera"], ros2=True)).entries] == [
        "camera", "ros2-bridge"]
    ctx = _ctx()
    ctx.config = parse_config("[ros2]\nenabled = true\n")
    assert "ros2-bridge" in {e.name for e in plan_up(ctx).entries}
    ctx.args.only = ["camera"]  # --only names exactly what starts
    assert [e.name for e in plan_up(ctx).entries] == ["camera"]


def test_identity_starts_only_with_up_identity_or_its_enabled_switch() -> None:
    """Face templates are biometric data: never started by a plain `up`."""
    assert "identity" not in {e.name for e in plan_up(_ctx()).entries}
    assert "identity" in {e.name for e in plan_up(_ctx(identity=True)).entries}
    ctx = _ctx()
    ctx.config = parse_config("[identity]\nenabled = true\n")
    assert "identity" in {e.name for e in plan_up(ctx).entries}


def test_connect_joins_without_a_router_and_not_with_listen() -> None:
    plan = plan_up(_ctx(connect=["tcp/127.0.0.1:9999"]))
    assert plan.joins and plan.connect == ["tcp/127.0.0.1:9999"]
    with pytest.raises(UsageError, match="not both"):
        plan_up(_ctx(connect=["tcp/127.0.0.1:9999"], listen=["tcp/127.0.0.1:9998"]))


def test_listen_defaults_to_the_configured_loopback_endpoint() -> None:
    """The TLS profile: `[zenoh] connect = ["tls/127.0.0.1:7447"]` makes `up` listen
    there with the config's Zenoh file, which children and router both get."""
    ctx = _ctx()
    ctx.config.zenoh.connect = ["tls/127.0.0.1:7447"]
    ctx.config.zenoh.config_file = "/etc/buddybot/zenoh/robot.json5"
    plan = plan_up(ctx)
    assert plan.listen == ["tls/127.0.0.1:7447"]
    assert plan.zenoh_file == "/etc/buddybot/zenoh/robot.json5"
    ctx.config.zenoh.connect = ["tls/buddy.local:7447"]  # a remote router: not ours to start
    assert plan_up(ctx).listen == ["tcp/127.0.0.1:7447"]


def test_a_service_given_up_is_down_even_if_its_name_is_alive() -> None:
    """A service that exited 2 because another of its name runs is not *ours*: the
    status line must not count it as up."""
    status = RobotStatus(expected=["camera", "face-detector"],
                         up=["camera", "face-detector"], given_up={"face-detector": 2})
    line = format_status(status, now=10.0)
    assert line.startswith("nodes 1/2 (down: face-detector) "
                           "(not restarted: face-detector exit 2) |")


# --- real processes --------------------------------------------------------------------


@contextlib.contextmanager
def reaped(up: Process) -> Iterator[list[psutil.Process]]:
    """Stop `up`; whatever it started is killed afterwards even if `up` misbehaves."""
    seen: list[psutil.Process] = []
    try:
        yield seen
    finally:
        with contextlib.suppress(psutil.Error):
            seen.extend(psutil.Process(up.pid).children(recursive=True))
        up.stop()
        for proc in seen:
            with contextlib.suppress(psutil.Error):
                proc.kill()


def _children(up: Process) -> list[psutil.Process]:
    found: list[psutil.Process] = []
    with contextlib.suppress(psutil.Error):
        found = psutil.Process(up.pid).children(recursive=True)
    return found


def test_apps_of_the_config_are_planned_with_their_node_names(tmp_path: Path) -> None:
    config = parse_config('[apps]\nrun = ["apps/hi.py:Hi", "mypkg.wave", "greeter"]\n',
                          str(tmp_path / "robot.toml"))
    assert plan_apps(config) == [AppLaunch("hi", f"{tmp_path / 'apps' / 'hi.py'}:Hi"),
                                 AppLaunch("wave", "mypkg.wave"),
                                 AppLaunch("greeter", "greeter")]
    assert plan_apps(default_config()) == []
    ctx = _ctx(config=str(tmp_path / "robot.toml"))
    argv = app_argv(AppLaunch("wave", "mypkg.wave"), ctx, ["tcp/127.0.0.1:9000"])
    assert argv[1:] == ["-m", "buddybot", "app", "run", "mypkg.wave", "--name", "wave",
                        "--connect", "tcp/127.0.0.1:9000", "--robot", "buddy",
                        "--log-level", "INFO", "--config", str(tmp_path / "robot.toml")]


@pytest.mark.integration
def test_apps_are_supervised_crashed_restarted_unloadable_left_down(tmp_path: Path) -> None:
    """An app that raises (exit 1) is restarted with backoff; one that cannot be loaded
    (exit 2) is reported once and not restarted; the status line counts both."""
    (tmp_path / "boom.py").write_text(
        "class Boom:\n    def run(self, bot, stop_event):\n"
        "        raise RuntimeError('boom')\n")
    (tmp_path / "two.py").write_text(
        "class A:\n    def run(self, bot, stop_event): ...\n"
        "class B:\n    def run(self, bot, stop_event): ...\n")
    config = tmp_path / "robot.toml"
    config.write_text('[apps]\nrun = ["boom.py", "two.py"]\n')
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--listen", f"tcp/127.0.0.1:{free_port()}",
                               "--status-period", "1", "--only", "people"), "up", tmp_path)
    with reaped(up):
        up.wait_for_output("restarting boom (restart 1)", 60)
        up.wait_for_output("two exited with status 2", 60)
        up.wait_for_output("restarting boom (restart 2)", 60)
        out = up.output()
        assert "RuntimeError: boom" in out and "2 app classes (A, B)" in out
        assert "restarting two" not in out and out.count("two exited with status") == 1
        last = [x for x in out.splitlines() if x.startswith("[status")][-1]
        assert "(not restarted: two exit 2)" in last and "nodes 1/3" in last, last
        assert up.alive()


@pytest.mark.integration
def test_busy_port_refused_in_one_line_and_nothing_started(router_process: Router,
                                                          tmp_path: Path) -> None:
    router = router_process
    t0 = time.monotonic()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", router.endpoint),
                 "up-busy", tmp_path)
    with reaped(up):
        started: set[int] = set()

        def exited() -> bool:
            started.update(p.pid for p in _children(up))
            return not up.alive()

        retry_until(exited, 30, 0.02, "up refusing")
        elapsed = time.monotonic() - t0
    out = up.output()
    assert up.proc.returncode == 1, out
    refusals = [x for x in out.splitlines() if "already in use" in x]
    assert len(refusals) == 1, out
    assert refusals[0].startswith(f"buddybot up: {router.endpoint} is already in use: "
                                  "a Zenoh router answers there")
    assert "Nothing started" in refusals[0]
    assert "Traceback" not in out and "starting router" not in out
    assert not any(line.startswith("[") for line in out.splitlines()), out
    # The only children `up` ever had were its own Zenoh probe helpers, if any:
    # never a `buddybot router` or `buddybot run`.
    assert not started, started
    assert elapsed < 20, f"refusal took {elapsed:.1f} s"
    assert router.alive()


@pytest.mark.integration
def test_a_service_exiting_2_is_reported_once_and_the_rest_runs(tmp_path: Path) -> None:
    config = tmp_path / "robot.toml"
    config.write_text('[face_detector]\nmodel_path = "no/such/model.tflite"\n')
    port = free_port()
    # --log-level WARNING: our router's readiness does not hang on its INFO lines.
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--listen", f"tcp/127.0.0.1:{port}", "--status-period", "1",
                               "--log-level", "WARNING",
                               "--only", "camera", "--only", "face-detector"), "up", tmp_path)
    with reaped(up):
        up.wait_for_output("face-detector exited with status 2", 120)
        seen_at = up.output().count("[status")
        # Long enough for restarts with backoff (1 s, 2 s, 4 s) to restart it twice.
        retry_until(lambda: up.output().count("[status") >= seen_at + 8, 60, 0.2,
                    "eight more status lines")
        out = up.output()
        assert out.count("face-detector exited with status") == 1, out
        assert "restarting face-detector" not in out
        last = [x for x in out.splitlines() if x.startswith("[status")][-1]
        assert "nodes 1/2 (down: face-detector) (not restarted: face-detector exit 2)" in last
        assert " camera " in last and "camera 0.0 fps" not in last  # still capturing
        camera = [c for c in _children(up) if "run camera" in " ".join(c.cmdline())]
        assert len(camera) == 1 and camera[0].is_running()
        assert up.alive()


@pytest.mark.integration
def test_only_with_a_typo_exits_2_naming_it(tmp_path: Path) -> None:
    up = Process(buddybot_argv("up", "--sim", "--only", "camra"), "up-typo", tmp_path)
    with reaped(up):
        assert up.proc.wait(60) == 2
    out = up.output()
    assert "--only: unknown service 'camra'" in out
    assert "camera" in out and "face-detector" in out  # the valid names are listed
    assert "Traceback" not in out and "starting router" not in out


@pytest.mark.integration
def test_connect_joins_a_running_router_without_starting_one(endpoint: str, tmp_path: Path
                                                              ) -> None:
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--connect", endpoint,
                               "--only", "radar-presence", "--status-period", "1"),
                 "up-join", tmp_path)
    with reaped(up):
        up.wait_for_output("nodes 1/1", 120)
        out = up.output()
        assert f"joining the router at {endpoint}" in out
        assert "[router" not in out
        cmdlines = [" ".join(c.cmdline()) for c in _children(up)]
        assert not any(" router" in c for c in cmdlines), cmdlines
        with Node("probe", connect=[endpoint], probe=True) as probe:
            assert "radar-presence" in probe.node_instances(timeout=5)


@pytest.mark.integration
def test_connect_to_nothing_fails_fast(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    up = Process(buddybot_argv("up", "--sim", "--connect", endpoint), "up-nothing", tmp_path)
    with reaped(up):
        assert up.proc.wait(60) == 1
    assert f"no router answers at {endpoint}" in up.output()


def _tls_profile(tmp_path: Path, port: int) -> Path:
    """A robot config for the TLS profile on one host: `[zenoh] connect` on loopback
    TLS and a Zenoh file the router (listen side) and every child (connect side) use."""
    certs = tmp_path / "certs"
    made = subprocess.run(["bash", str(REPO / "scripts" / "make-test-certs.sh"), str(certs)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert made.returncode == 0, made.stderr
    zenoh_file = tmp_path / "robot-tls.json5"
    zenoh_file.write_text(json.dumps({"transport": {"link": {
        "protocols": ["tls"],
        "tls": {
            "root_ca_certificate": str(certs / "ca.pem"),
            "listen_private_key": str(certs / "router.key"),
            "listen_certificate": str(certs / "router.pem"),
            "connect_private_key": str(certs / "robot.key"),
            "connect_certificate": str(certs / "robot.pem"),
            "enable_mtls": True,
            "verify_name_on_connect": True,
        },
    }}}))
    config = tmp_path / "robot.toml"
    config.write_text(f'[zenoh]\nconnect = ["tls/127.0.0.1:{port}"]\n'
                      f'config_file = "{zenoh_file.name}"\n')  # relative to the TOML file
    return config


@pytest.mark.integration
def test_up_with_the_tls_profile(tmp_path: Path) -> None:
    """`[zenoh] config_file`: the router listens with it, the services and the status
    probe connect with it; plain TCP gets nothing; doctor sees transport tls."""
    port = free_port()
    config = _tls_profile(tmp_path, port)
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--only", "radar-presence", "--only", "controller",
                               "--status-period", "1"), "up-tls", tmp_path)
    with reaped(up):
        up.wait_for_output("nodes 2/2", 120)
        assert f"starting router on tls/127.0.0.1:{port}" in up.output()
        router = [c for c in _children(up) if " router " in " ".join(c.cmdline())]
        assert len(router) == 1
        assert str(tmp_path / "robot-tls.json5") in router[0].cmdline()
        doctor = Process(buddybot_argv("doctor", "--config", str(config), "--expect",
                                       "radar-presence", "--expect", "controller", "--sim",
                                       "--timeout", "5", "--window", "0.5"), "doctor-tls",
                         tmp_path)
        assert doctor.proc.wait(60) == 0, doctor.output()
        out = doctor.output()
        assert f"reachable at tls/127.0.0.1:{port} (transport tls)" in out
        assert "2/2 alive" in out
        doctor.stop()
        # Nothing answers in clear on the robot's port.
        plain = f"tcp/127.0.0.1:{port}"
        with pytest.raises(ConnectionError):
            config_plain = zenoh_config(connect=[plain])
            config_plain.insert_json5("connect/timeout_ms", "1500")
            Node("plain-probe", connect=[plain], config=config_plain, probe=True).close()


@pytest.mark.integration
def test_a_router_that_cannot_listen_stops_up_before_any_service(tmp_path: Path) -> None:
    """Ready means *our* router logged that it listens, not "something accepts on the
    port": a router that dies first (here: an address not on this host) ends `up`
    with one line, and no service is started to join whatever answers there."""
    endpoint = f"tcp/192.0.2.1:{free_port()}"  # TEST-NET-1: never a local address
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", endpoint,
                               "--only", "radar-presence"), "up-norouter", tmp_path)
    with reaped(up):
        assert up.proc.wait(60) == 1
    out = up.output()
    assert (f"buddybot up: the router exited with status 1 before listening on {endpoint}"
            in out), out
    assert "[radar-presence" not in out


@pytest.mark.integration
def test_router_port_taken_while_it_restarts_stops_up(tmp_path: Path) -> None:
    """The router dies and another program takes its port before the restart: `up`
    stops everything instead of letting its services join a stranger."""
    port = free_port()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen",
                               f"tcp/127.0.0.1:{port}", "--only", "radar-presence",
                               "--status-period", "1"), "up-stolen", tmp_path)
    with reaped(up), socket.socket() as thief:
        up.wait_for_output("nodes 1/1", 120)
        router = [c for c in _children(up) if " router " in " ".join(c.cmdline())]
        assert len(router) == 1
        router[0].kill()
        router[0].wait(10)
        thief.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        thief.bind(("127.0.0.1", port))  # within the 1 s before the restart
        thief.listen(8)
        assert up.proc.wait(60) == 1
        out = up.output()
        assert f"tcp/127.0.0.1:{port} is already in use" in out
        assert "Stopping everything." in out
        assert "restarting router" not in out
