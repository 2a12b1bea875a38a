"""`buddybot doctor`: is this robot healthy, and if not, what exactly is wrong?

Each check is a small function returning a `Check` (name, OK/WARN/FAIL,
one line of detail), so the verdicts are tested on crafted inputs without a
robot. Two families:

* quick checks need no running robot (config, devices, versions, the router
  port): `buddybot up` runs them at start and prints their summary;
* bus checks ask a running robot (router, live nodes, sensor rates, the eye
  page, clocks), each bounded by a timeout so `doctor` never hangs on a dead
  or silent bus.

Pure where it can be: the functions that judge (`judge_rate`, `judge_nodes`,
`judge_clock`...) take numbers and lists; the ones that look (`probe_bus`,
`port_users`...) are thin and kept apart. What is particular to a service (its
devices, its packages, its stream's rate) is the service's own, lent through the
registry (`runtime.health.DoctorHooks`).
"""

from __future__ import annotations

import importlib.metadata
import json
import platform
import socket
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any
from urllib.parse import urlsplit

from buddybot.runtime import enabled, endpoints, registry
from buddybot.runtime.config import DEFAULT_ENDPOINT, ConfigBase
from buddybot.runtime.health import FAIL, OK, WARN, Check, DoctorHooks, Rate
from buddybot.runtime.rates import count_hz

CLOCK_MIN_EPOCH_S = 1_704_067_200.0
"""2024-01-01T00:00:00Z: a system clock before this was never set (no RTC, no NTP)."""
CLOCK_SKEW_WARN_S = 2.0
"""A received stamp further than this from our clock: two hosts disagree on the time."""
RATE_WARN_FRACTION = 0.5
"""A stream below this fraction of its expected rate is a warning."""
VERSION_PACKAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("buddybot", ("buddybot",)),
    ("zenoh", ("eclipse-zenoh",)),
    ("msgspec", ("msgspec",)),
    ("numpy", ("numpy",)),
)
"""(shown name, distribution names to try): what a bug report needs to name; each
service adds its own (`DoctorHooks.packages`)."""


# --- report -------------------------------------------------------------------------


def format_report(checks: Sequence[Check]) -> str:
    """One line per check, aligned, then the summary line."""
    width = max((len(c.name) for c in checks), default=0)
    lines = [f"{c.level:<4}  {c.name:<{width}}  {c.detail}" for c in checks]
    lines.append(summary(checks))
    return "\n".join(lines)


def summary(checks: Sequence[Check]) -> str:
    """One line: counts, and the names of what is not OK (`up` prints this)."""
    counts = {level: sum(c.level == level for c in checks) for level in (OK, WARN, FAIL)}
    text = f"doctor: {counts[OK]} ok, {counts[WARN]} warn, {counts[FAIL]} fail"
    bad = [f"{c.name} ({c.level})" for c in checks if c.level != OK]
    return text + (f": {', '.join(bad)}" if bad else "")


def to_json(checks: Sequence[Check]) -> str:
    return json.dumps({"ok": not any(c.failed for c in checks),
                       "checks": [asdict(c) for c in checks]}, indent=2)


def exit_code(checks: Sequence[Check]) -> int:
    """1 when any check failed, else 0 (warnings are not failures)."""
    return 1 if any(c.failed for c in checks) else 0


# --- judging (pure) -----------------------------------------------------------------


def judge_config(config: ConfigBase | None, error: str | None) -> Check:
    if config is None:
        return Check("config", FAIL, error or "not loaded")
    return Check("config", OK, config.source or "defaults (no config file)")


def describe_holder(nodes: list[str] | None, process: str | None = None) -> str:
    """Who holds a port, in words: a Zenoh router (with whose nodes) or a stranger;
    and the local process when it is known (`port_holder`)."""
    if nodes is None:
        who = "something that is not a Zenoh router"
    elif nodes:
        who = f"a Zenoh router (live nodes: {', '.join(nodes)})"
    else:
        who = "a Zenoh router (no live BuddyBot nodes)"
    return who + (f", process {process}" if process else "")


def judge_port(endpoint: str, accepting: bool, nodes: list[str] | None,
               process: str | None = None) -> Check:
    """The router port before `up`: free, our kind of router, or a stranger.

    `nodes` is what a Zenoh probe found there (None: no Zenoh router answered);
    `process` the local process listening there, when `port_holder` can tell.
    """
    name = "router port"
    if not accepting:
        return Check(name, OK, f"{endpoint} is free")
    held = f", process {process}" if process else ""
    if nodes is None:
        return Check(name, FAIL, f"{endpoint} is taken by something that is not a Zenoh "
                     f"router{held}")
    who = f"live nodes: {', '.join(nodes)}" if nodes else "no live BuddyBot nodes"
    return Check(name, OK, f"{endpoint}: a Zenoh router runs there ({who}){held}")


def judge_router(endpoint: str, reachable: bool, error: str = "") -> Check:
    transport = endpoint.partition("/")[0] or "?"
    if reachable:
        return Check("router", OK, f"reachable at {endpoint} (transport {transport})")
    why = error.split(". Retry")[0] if error else "nothing answers"
    why = why.removeprefix(f"no Zenoh router at {endpoint}: ")  # we say where already
    return Check("router", FAIL, f"{endpoint} (transport {transport}): {why}")


def judge_nodes(expected: Iterable[str], live: dict[str, set[str]]) -> Check:
    """Every expected node alive, exactly once."""
    expected = list(expected)
    missing = [n for n in expected if n not in live]
    dupes = sorted(n for n, ids in live.items() if len(ids) > 1)
    extra = sorted(n for n in live if n not in expected)
    alive = f"{len(expected) - len(missing)}/{len(expected)} alive"
    if missing:
        return Check("nodes", FAIL, f"{alive}; missing: {', '.join(missing)}")
    if dupes:
        return Check("nodes", WARN, f"{alive}; more than one instance of: {', '.join(dupes)}")
    return Check("nodes", OK, alive + (f" (also: {', '.join(extra)})" if extra else ""))


def judge_rate(name: str, count: int, window_s: float, expected_hz: float) -> Check:
    """A stream's measured rate against what it should be."""
    hz = count_hz(count, window_s)
    text = f"{hz:.1f} Hz over {window_s:.1f} s (expected ~{expected_hz:g} Hz)"
    if count == 0:
        return Check(name, FAIL, f"nothing received in {window_s:.1f} s "
                     f"(expected ~{expected_hz:g} Hz)")
    if hz < expected_hz * RATE_WARN_FRACTION:
        return Check(name, WARN, text)
    return Check(name, OK, text)


def judge_clock(wall_s: float, mono_before: float, mono_after: float,
                stamp_ns: int | None = None) -> Check:
    """Wall clock set (after 2024), monotonic clock not going back, and, if a message
    was received, its stamp near our time (the sender's clock agrees with ours)."""
    if wall_s < CLOCK_MIN_EPOCH_S:
        return Check("clock", FAIL, f"system time {time.strftime('%Y-%m-%d', time.gmtime(wall_s))}"
                     " is before 2024: set the clock (NTP, RTC)")
    if mono_after < mono_before:
        return Check("clock", FAIL, "the monotonic clock went backwards")
    if stamp_ns is not None:
        skew = wall_s - stamp_ns / 1e9
        if abs(skew) > CLOCK_SKEW_WARN_S:
            return Check("clock", WARN, f"a received message is stamped {skew:+.1f} s from "
                         "our clock: the hosts disagree on the time (NTP?)")
        return Check("clock", OK, f"set; a received stamp is {skew * 1000:+.0f} ms from ours")
    return Check("clock", OK, "set (after 2024), monotonic")


def judge_versions(found: dict[str, str | None]) -> Check:
    """Versions of what BuddyBot runs on; a missing one is a warning (its service
    cannot start, the others can)."""
    text = ", ".join(f"{k} {v or 'MISSING'}" for k, v in found.items())
    missing = [k for k, v in found.items() if v is None]
    return Check("versions", WARN if missing else OK, text)


# --- looking (thin) -----------------------------------------------------------------


def service_hooks() -> list[tuple[registry.Entry, DoctorHooks]]:
    """Every service's part of doctor, in the registry's order (the order of the
    report's lines); a service whose module is not installed has none."""
    found = []
    for entry in registry.SERVICES:
        try:
            hooks = entry.doctor_hooks()
        except ImportError:
            continue
        if hooks is not None:
            found.append((entry, hooks))
    return found


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    packages = list(VERSION_PACKAGES)
    for _entry, hooks in service_hooks():
        packages += hooks.packages
    for shown, dists in packages:
        out[shown] = None
        for dist in dists:
            try:
                out[shown] = importlib.metadata.version(dist)
                break
            except importlib.metadata.PackageNotFoundError:
                continue
    return out


def check_display(host: str, port: int, timeout: float) -> Check:
    """The eye renderer's page server answers `/healthz` at `host:port` (a
    wildcard host means this machine)."""
    return check_display_url(_http_base(endpoints.local_host(host), port), timeout)


def check_display_url(base: str, timeout: float, where: str = "") -> Check:
    """The page server at `base` (`http://host:port`) answers `/healthz`; `where`
    says whose it is (shown after the verdict)."""
    url = f"{base.rstrip('/')}/healthz"
    note = f" ({where})" if where else ""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as reply:
            return Check("displays", OK, f"eye page server answers at {url} "
                         f"(HTTP {reply.status}){note}")
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        return Check("displays", FAIL, f"eye page server does not answer at {url}: "
                     f"{reason}{note}")


# --- where the eye pages are (pure) ------------------------------------------------

EYE_RENDERER = "eye-renderer"


def _http_base(host: str, port: int) -> str:
    return f"http://{endpoints.join_host_port(host, port)}"


def is_local_host(host: str, own_names: Iterable[str], own_addresses: Iterable[str]) -> bool:
    """Whether `host` (a configured address or name) means this machine: a
    wildcard, loopback, one of its names or one of its interface addresses.
    Pure, and never asks DNS (a remote name that does not answer must not
    make doctor hang)."""
    h = host.strip("[]").lower().rstrip(".")
    return (endpoints.is_wildcard(host) or endpoints.is_loopback(h)
            or h in {n.lower() for n in own_names} or h in set(own_addresses))


def plan_display(*, alive: bool, values: Mapping[str, Any] | None, config_host: str,
                 config_port: int, expected: bool, hostname: str, local: bool
                 ) -> tuple[str, str] | Check | None:
    """Where to look for the eye pages: (base URL, whose), a verdict without
    looking, or None (no display check).

    The rule follows the deployment, not this host's config:

    1. The eye-renderer is alive on the bus (its liveliness token): ask it.
       Its diagnostics (`values`) say `url` (as its own host reaches the
       pages), `listen_host` (what it binds) and `hostname`. Same host as
       ours: check `url`. Another host: check its `listen_host`, or its
       `hostname` when it serves every interface; if it serves only its own
       loopback, nobody here can reach it: WARN, run doctor there.
       Alive but silent about where it serves (no diagnostics within the
       timeout): fall back on the config's host and port (WARN when the port
       is 0, any free port, so unknown).
    2. Not alive, and the config puts it on another host (`local` false):
       WARN "eye-renderer not running here" (this host is not where it runs;
       its own host's doctor says why it is down).
    3. Not alive, the config puts it here and it is `expected`: check the
       config's host and port (FAIL when nothing answers, the node check
       says it is missing too).
    4. Not alive, here, not expected: no check.
    """
    if alive and values and isinstance(values.get("url"), str):
        url = str(values["url"])
        theirs = str(values.get("hostname") or hostname)
        if theirs == hostname:
            return url, f"{EYE_RENDERER} on this host"
        try:
            port = urlsplit(url).port or 80
        except ValueError:
            return Check("displays", WARN, f"{EYE_RENDERER} on {theirs} reports an unusable "
                         f"address {url!r}")
        listen = str(values.get("listen_host", ""))
        if endpoints.is_wildcard(listen):
            return _http_base(theirs, port), f"{EYE_RENDERER} on {theirs}"
        if endpoints.is_loopback(listen):
            return Check("displays", WARN, f"{EYE_RENDERER} runs on {theirs} and serves only "
                         f"its own loopback ({url}): not reachable from here; run "
                         f"`buddybot doctor` on {theirs}")
        return _http_base(listen, port), f"{EYE_RENDERER} on {theirs}"
    here = endpoints.local_host(config_host)
    if alive:
        if config_port == 0:
            return Check("displays", WARN, f"{EYE_RENDERER} is running but did not say where "
                         "it serves, and the config's port is 0 (any free port)")
        return _http_base(here, config_port), \
            f"{EYE_RENDERER} did not say where it serves: the config's address"
    if not local:
        return Check("displays", WARN, f"{EYE_RENDERER} not running here: the config serves "
                     f"the eye pages from {_http_base(config_host, config_port)} (another host) "
                     "and no eye-renderer is on the bus")
    if not expected:
        return None
    return _http_base(here, config_port), "the config's address"


def own_names() -> frozenset[str]:
    """This machine's names (no DNS)."""
    return endpoints.host_names(socket.gethostname())


def own_addresses() -> set[str]:
    """This machine's interface addresses, when psutil can list them."""
    try:
        import psutil

        return {a.address.split("%")[0].lower() for addrs in psutil.net_if_addrs().values()
                for a in addrs if a.family in (socket.AF_INET, socket.AF_INET6)}
    except Exception:
        return set()


def renderer_is_local(config: ConfigBase) -> bool:
    """Whether the config serves the eye pages from this machine."""
    if "eye_renderer" not in set(config.__struct_fields__):
        return True
    return is_local_host(str(config.eye_renderer.host), own_names(), own_addresses())


def expected_here(names: Iterable[str], config: ConfigBase | None) -> list[str]:
    """The nodes doctor expects when not told (`--expect`): every installed
    service, except the eye-renderer when the config serves the eye pages
    from another host (it runs there; the displays check still looks for it)."""
    away = config is not None and not renderer_is_local(config)
    return [n for n in names if not (away and n == EYE_RENDERER)]


def expected_nodes(config: ConfigBase, installed: Iterable[registry.Entry], sim: bool
                   ) -> list[str]:
    """The nodes doctor expects when not told (`--expect`): the services the config
    enables (`enabled.enabled_services`, as `up` starts them) and its apps, less
    what runs on another host (`expected_here`)."""
    services = [e.name for e in enabled.enabled_services(config, installed, sim=sim)]
    return expected_here(services + enabled.app_names(config), config)


def display_check(config: ConfigBase, bus: BusReport, expected: bool, timeout: float
                  ) -> Check | None:
    """The displays check of `bus_checks`: `plan_display`, then a look at the URL."""
    if "eye_renderer" not in set(config.__struct_fields__):
        return None
    cfg = config.eye_renderer
    plan = plan_display(
        alive=EYE_RENDERER in bus.live, values=bus.diagnostics.get(EYE_RENDERER),
        config_host=str(cfg.host), config_port=int(cfg.port), expected=expected,
        hostname=socket.gethostname(), local=renderer_is_local(config))
    if plan is None or isinstance(plan, Check):
        return plan
    base, whose = plan
    return check_display_url(base, timeout, whose)


# --- the bus ------------------------------------------------------------------------


@dataclass
class BusReport:
    """What one bounded look at the bus found (filled by `probe_bus`)."""

    endpoint: str
    reachable: bool = False
    error: str = ""
    live: dict[str, set[str]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    """Samples per stream name over `window_s`."""
    window_s: float = 0.0
    last_stamp_ns: int | None = None
    diagnostics: dict[str, dict[str, Any]] = field(default_factory=dict)
    """The latest diagnostics values per node seen during the look."""


def probe_bus(endpoint: str, robot: str, zenoh_file: str | None, timeout: float,
              window_s: float, streams: Mapping[str, Sequence[str]], *,
              all_robots: bool = False,
              stop: threading.Event | None = None,
              wait_values: Mapping[str, str] | None = None) -> BusReport:
    """Open a probe on `endpoint` (giving up after `timeout`), list the live nodes (of
    every robot, as `robot/name`, with `all_robots`) and count the samples of
    `streams` (name -> absolute keys, all counted under the name) for `window_s`
    seconds.

    Diagnostics values seen meanwhile are kept per node. `wait_values` (node ->
    a value name): for each such node that is alive, wait past the window (at
    most `timeout`) until its diagnostics carry that value (they come every 2 s)."""
    from buddybot.contract import keys
    from buddybot.contract import messages as m
    from buddybot.runtime.node import Node, zenoh_config

    report = BusReport(endpoint)
    try:
        config = zenoh_config(connect=[endpoint], base_file=zenoh_file)
        config.insert_json5("connect/timeout_ms", str(max(1, int(timeout * 1000))))
        node = Node("doctor", robot=robot, connect=[endpoint], config=config, probe=True,
                    stop_event=stop)
    except KeyboardInterrupt:
        report.error = "interrupted"
        return report
    except Exception as exc:  # ConnectionError: no router, or it refused us (TLS)
        report.error = str(exc)
        return report
    lock = threading.Lock()
    with node:
        report.reachable = True
        report.live = node.node_instances(all_robots=all_robots, timeout=timeout)
        counts = dict.fromkeys(streams, 0)

        def counter(name: str) -> Callable[[str, bytes, str], None]:
            def on_sample(_key: str, _payload: bytes, _encoding: str) -> None:
                with lock:
                    counts[name] += 1
            return on_sample

        wanted = {n: v for n, v in (wait_values or {}).items() if n in report.live}
        have_values = threading.Event()
        if not wanted:
            have_values.set()

        def on_diagnostics(_key: str, payload: bytes, _encoding: str) -> None:
            try:
                msg = keys.DIAGNOSTICS.codec.decode(payload, m.DiagnosticStatus)
            except Exception:
                return
            with lock:
                report.last_stamp_ns = msg.stamp_ns
                report.diagnostics[msg.node] = dict(msg.values)
                if all(v in report.diagnostics.get(n, {}) for n, v in wanted.items()):
                    have_values.set()

        subs = [node.subscribe_raw(key, counter(name)) for name, keys_ in streams.items()
                for key in keys_]
        subs.append(node.subscribe_raw(node.key(keys.DIAGNOSTICS), on_diagnostics))
        start = time.monotonic()
        node.stop_event.wait(window_s)
        with lock:
            report.window_s = time.monotonic() - start
            report.counts = dict(counts)
        deadline = time.monotonic() + timeout
        while not have_values.wait(0.1) and not node.stop_event.is_set() \
                and time.monotonic() < deadline:
            pass
        for sub in subs:
            sub.close()
    return report


# --- the two families ---------------------------------------------------------------


@dataclass
class Options:
    """What the checks need to know besides the config."""

    sim: bool = False
    endpoint: str = DEFAULT_ENDPOINT
    robot: str = "buddy"
    expected: list[str] = field(default_factory=list)
    timeout: float = 3.0
    window_s: float = 2.0
    zenoh_file: str | None = None
    stop: threading.Event | None = None
    """Set by Ctrl-C: a wait on the bus ends early."""


def quick_checks(config: ConfigBase | None, config_error: str | None, opts: Options,
                 *, port: bool = True, in_use: frozenset[str] = frozenset()) -> list[Check]:
    """Checks that need no running robot: config, devices, versions, router port.

    `in_use`: services running now (their devices are not opened again)."""
    checks = [judge_config(config, config_error)]
    if config is not None:
        for entry, hooks in service_hooks():
            settings = getattr(config, entry.table or "", None)
            if hooks.devices is not None and settings is not None:
                checks += hooks.devices(settings, opts.sim, entry.name in in_use)
    checks.append(judge_versions(versions()))
    if port:
        checks.append(port_check(opts.endpoint, opts.zenoh_file, opts.timeout, opts.robot))
    return checks


def port_check(endpoint: str, zenoh_file: str | None, timeout: float,
               robot: str = "buddy") -> Check:
    """Who holds the router's port: nobody, a Zenoh router (with whose nodes), or not
    a Zenoh router at all."""
    if not endpoints.accepting(endpoint):
        return judge_port(endpoint, False, None)
    return judge_port(endpoint, True, *port_users(endpoint, zenoh_file, timeout, robot))


def port_users(endpoint: str, zenoh_file: str | None, timeout: float,
               robot: str = "buddy") -> tuple[list[str] | None, str | None]:
    """Who answers on a port that accepts connections: the live nodes behind a
    Zenoh router there (None: not a Zenoh router), and the local process
    (`port_holder`). The one busy-port look shared by `doctor`, `up`'s quick
    doctor and `buddybot router`."""
    bus = probe_bus(endpoint, robot, zenoh_file, timeout, 0.0, {}, all_robots=True)
    return (sorted(bus.live) if bus.reachable else None), endpoints.port_holder(endpoint)


def expected_rates(config: ConfigBase, expected: Iterable[str], sim: bool) -> list[Rate]:
    """The streams the expected services publish with this config (an LD2450 robot's
    radar bridge `targets`, not `frames`), as each service's hook says."""
    wanted = set(expected)
    return [rate for entry, hooks in service_hooks()
            if hooks.rates is not None and entry.name in wanted
            for rate in hooks.rates(getattr(config, entry.table or "", None), sim)]


def bus_checks(config: ConfigBase, opts: Options) -> tuple[list[Check], frozenset[str]]:
    """Checks that ask the running robot, each bounded by `opts.timeout`; and the
    names of the live nodes (whose devices the quick checks must not open again)."""
    from buddybot.contract import keys
    rates = expected_rates(config, opts.expected, opts.sim)
    prefix = keys.prefix(opts.robot)
    streams = {rate.name: [f"{prefix}/{key}" for key in (rate.key, *rate.also)]
               for rate in rates}
    bus = probe_bus(opts.endpoint, opts.robot, opts.zenoh_file, opts.timeout,
                    opts.window_s if streams else 0.0, streams, stop=opts.stop,
                    wait_values={EYE_RENDERER: "url"})
    error = bus.error
    if not bus.reachable and endpoints.over_tcp(opts.endpoint) \
            and not endpoints.accepting(opts.endpoint):
        error = "nothing listens there (is the router or `buddybot up` running?)"
    checks = [judge_router(opts.endpoint, bus.reachable, error)]
    if not bus.reachable:
        return checks, frozenset()
    checks.append(judge_nodes(opts.expected, bus.live))
    checks += [judge_rate(rate.name, bus.counts[rate.name], bus.window_s, rate.hz)
               for rate in rates]
    display = display_check(config, bus, EYE_RENDERER in opts.expected, opts.timeout)
    if display is not None:
        checks.append(display)
    checks.append(clock_check(bus.last_stamp_ns))
    return checks, frozenset(bus.live)


def clock_check(stamp_ns: int | None = None) -> Check:
    before = time.monotonic()
    wall = time.time()
    return judge_clock(wall, before, time.monotonic(), stamp_ns)
