"""The Zenoh session of a BuddyBot process: its configuration and its opening.

Written once for every process (services, probes, the router): explicit
endpoints, multicast scouting off, clients that wait for their router and
reconnect quickly, a stalled link closed after 100 ms instead of 5 s, and
no message larger than the largest image we accept.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import logging
import os
import re
import select
import socket
import sys
import threading
import time
from typing import Any, Literal

import zenoh
import zenoh.ext

from buddybot.contract import keys
from buddybot.runtime.endpoints import parse as parse_endpoint
from buddybot.runtime.errors import BuddyBotError, ConfigError
from buddybot.runtime.nesting import TooDeep, check_depth

log = logging.getLogger("buddybot.node")


class RouterUnreachable(BuddyBotError, ConnectionError):
    """No router answered within a probe's connect timeout (exit status 1).

    Also a ConnectionError: it is one, and code that waits for a router
    without caring whose error it is (`up`'s status probe) catches it as such."""


# --- Zenoh's own log, routed into ours ---------------------------------------------
#
# Zenoh (Rust) logs to file descriptor 1 only. Left there, it would mix with
# what `echo` prints, and without it nobody sees why a connection fails
# (refused, TLS only, ...). So fd 1 becomes a pipe: a reader thread turns
# Zenoh's lines into records of the `zenoh` logger (stderr, our format and
# level) and passes anything else through to the real stdout, where Python's
# `sys.stdout` now writes directly. Connection failures are logged by Zenoh
# at DEBUG only: they are always captured (shown at our DEBUG) and kept per
# endpoint, so "no router" can say why.

_ZENOH_LEVELS = {"DEBUG": "debug", "INFO": "warn", "WARNING": "warn", "ERROR": "error"}
"""Our `--log-level` -> Zenoh's: its INFO is chatty, so INFO shows Zenoh's WARN."""
_REASONS_TARGET = "zenoh::net::runtime::orchestrator"
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_LINE = re.compile(  # time, level, thread, [spans], target: message
    r"^\d{4}-\d\d-\d\dT\S+\s+(TRACE|DEBUG|INFO|WARN|ERROR)\s+(?:ThreadId\(\d+\)\s+)?"
    r"(?:.*?\s)??((?:\w+::)*\w+):\s(.*)$")
_UNABLE = re.compile(r"Unable to connect to (?:configured peer )?(\S+?)! (.*)$")
_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+\.?|\.?\s*Retry in \d+\s*m?s\.?")
_INNER = re.compile(r"\[(?:[\w.\-\[\]]+:\d+: )?([^\[\]]+)\]")
_PY_LEVEL = {"TRACE": logging.DEBUG, "DEBUG": logging.DEBUG, "INFO": logging.INFO,
             "WARN": logging.WARNING, "ERROR": logging.ERROR}
_SYNC = b"\x00buddybot-zenoh-log-sync\n"
_routed = threading.Event()
_synced = threading.Condition()
_sync_count = 0
_failures: dict[str, str] = {}


def _clean(text: str) -> str:
    """Zenoh's message without its Rust source locations."""
    return _LOCATION.sub("", text).strip()


def _short_reason(text: str) -> str:
    """The operating system's or TLS layer's words inside Zenoh's wrapping
    (`... [127.0.0.1:1: Connection refused (os error 111)]` -> the last part)."""
    text = _clean(text)
    inner = _INNER.findall(text)
    return inner[-1].strip() if inner else text


def connect_failures() -> dict[str, str]:
    """Endpoint -> the reason of its latest failed connection attempt (empty
    unless Zenoh's log is routed)."""
    with _synced:
        return dict(_failures)


def forget_connect_failures() -> None:
    with _synced:
        _failures.clear()


def route_zenoh_log(level: str) -> bool:
    """Send Zenoh's log into Python logging at our `level` (once per process).

    False (nothing done) when stdout is not this process's own fd 1 (tests
    capturing it in-process), or when already routed. `RUST_LOG`, if set,
    still wins for the level, as Zenoh documents.

    Fd 1 becomes the write end of a pipe (`open_log_pipe`) that a Python
    thread reads. That end is non-blocking, a trade-off: the reader needs
    the GIL, and if it is starved while Zenoh floods lines (its DEBUG during
    a reconnect storm), a blocking pipe would fill and park Zenoh's own
    threads in `write(1)` (keepalives, routing, every session's traffic)
    until Python reads again. Non-blocking, a write to a full pipe fails at
    once: Rust's tracing writer reports the failed write on stderr and goes
    on, so those log lines are lost, never the bus (on a router at
    RUST_LOG=trace whose reader gets no GIL for 8 s, a blocking pipe stops
    the samples routed through it for 7.9 s; non-blocking, the longest gap
    is 14 ms and 4583 lines are dropped, each one a line of Rust's
    on stderr, which stays blocking). The reader counts how
    often it finds the pipe full (`zenoh_log_overflows`) and logs
    a warning at most once per `OVERFLOW_LOG_PERIOD_S`. Anything else that
    writes to fd 1 shares the non-blocking end: a child process inheriting
    it could see EAGAIN, which is why every child we start gets its own
    stdout (a pipe, DEVNULL or captured).
    """
    if _routed.is_set():
        return False
    old = sys.stdout
    try:
        if old is not sys.__stdout__ or old is None or old.fileno() != 1:
            return False
    except (AttributeError, ValueError, io.UnsupportedOperation):
        return False
    _routed.set()
    old.flush()
    real_stdout = os.dup(1)
    read_end, write_end = open_log_pipe()
    os.dup2(write_end, 1)  # shares the open file description: non-blocking too
    os.close(write_end)
    line_buffered = bool(getattr(old, "line_buffering", False)
                         or getattr(old, "write_through", False))
    sys.stdout = open(real_stdout, "w", buffering=1 if line_buffered else -1,  # noqa: SIM115
                      encoding=old.encoding, errors=old.errors)
    passthrough = os.dup(real_stdout)
    threading.Thread(target=_pump_zenoh_log, args=(read_end, passthrough),
                     name="zenoh-log", daemon=True).start()
    zenoh_level = _ZENOH_LEVELS.get(level, "warn")
    if zenoh_level != "debug":
        zenoh_level += f",{_REASONS_TARGET}=debug"
    zenoh.init_log_from_env_or(zenoh_level)
    return True


LOG_PIPE_BYTES = 1 << 20
"""Room in Zenoh's log pipe for bursts (Zenoh at DEBUG) while the reader waits
for the GIL (the kernel's default is 64 KiB)."""
OVERFLOW_LOG_PERIOD_S = 10.0
"""At most one warning about dropped Zenoh lines per this many seconds."""
_overflow = {"count": 0, "logged_at": -1e9}


def open_log_pipe() -> tuple[int, int]:
    """(read end, write end) of the pipe Zenoh's log goes through: `LOG_PIPE_BYTES`
    large where the kernel allows it, and the write end non-blocking, so that a
    full pipe drops lines instead of blocking whoever writes (see
    `route_zenoh_log`). The read end stays blocking for the reader thread."""
    read_end, write_end = os.pipe()
    with contextlib.suppress(AttributeError, OSError):
        fcntl.fcntl(write_end, fcntl.F_SETPIPE_SZ, LOG_PIPE_BYTES)
    os.set_blocking(write_end, False)
    return read_end, write_end


def zenoh_log_overflows() -> int:
    """How many times the reader found Zenoh's log pipe full (writes failing: lines
    were dropped unless Zenoh wrote nothing while it was full)."""
    with _synced:
        return int(_overflow["count"])


def _full(write_fd: int) -> bool:
    """Whether a write to the pipe would fail now: poll(2) says POLLOUT on a pipe
    while it has a free page, which is what a writer needs (one cheap
    syscall). An fd that is no longer open is not full."""
    poller = select.poll()
    poller.register(write_fd, select.POLLOUT)
    events = poller.poll(0)
    if not events:
        return True
    revents = events[0][1]
    return not revents & (select.POLLOUT | select.POLLNVAL | select.POLLERR)


def _note_overflow(now: float) -> None:
    with _synced:
        _overflow["count"] += 1
        count = int(_overflow["count"])
        if now - _overflow["logged_at"] < OVERFLOW_LOG_PERIOD_S:
            return
        _overflow["logged_at"] = now
    log.warning("Zenoh's log pipe was full (%d times so far): some of Zenoh's log lines "
                "were dropped rather than stall Zenoh", count)


def _pump_zenoh_log(read_fd: int, passthrough_fd: int, write_fd: int = 1) -> None:
    """Zenoh's lines -> the `zenoh` logger; anything else -> the real stdout.

    Before each read it asks whether the pipe is full (`_full` on the write
    end, fd 1): a pipe found full is one overflow, counted once until it has
    room again. The reader holds no write end of its own, so it ends at
    end of file when the last writer goes away."""
    zlog = logging.getLogger("zenoh")
    was_full = False
    rest = b""
    with open(read_fd, "rb", buffering=0) as pipe:
        while True:
            full = _full(write_fd)
            if full and not was_full:
                _note_overflow(time.monotonic())
            was_full = full
            chunk = pipe.read(1 << 16)
            if not chunk:
                break
            rest += chunk
            *lines, rest = rest.split(b"\n")
            for raw in lines:
                _zenoh_line(raw + b"\n", zlog, passthrough_fd)
            if len(rest) > LOG_PIPE_BYTES:  # no newline in sight (binary output)
                _zenoh_line(rest, zlog, passthrough_fd)
                rest = b""
    if rest:
        _zenoh_line(rest, zlog, passthrough_fd)


def _zenoh_line(raw: bytes, zlog: logging.Logger, passthrough_fd: int) -> None:
    """One line from the pipe: a sync marker, one of Zenoh's, or someone else's."""
    global _sync_count
    if raw == _SYNC:
        with _synced:
            _sync_count += 1
            _synced.notify_all()
        return
    line = _ANSI.sub("", raw.decode("utf-8", "replace")).rstrip("\n")
    found = _LINE.match(line)
    if found is None:
        with contextlib.suppress(OSError):  # a child's output, say: not ours to hide
            os.write(passthrough_fd, raw)
        return
    level, target, text = found.groups()
    ours = target == _REASONS_TARGET
    unable = _UNABLE.search(text) if ours else None
    if unable is not None:
        with _synced:
            _failures[unable[1]] = _short_reason(unable[2])
    # Only captured for the reasons (Zenoh's level for it is DEBUG), and
    # "Unable to connect to any of [...]. Timeout!", which the probe's
    # own error line says with the reason: both for our DEBUG only.
    quiet = ours and (_PY_LEVEL[level] < logging.WARNING
                      or "Unable to connect to any of" in text)
    zlog.log(logging.DEBUG if quiet else _PY_LEVEL[level], "%s: %s", target, _clean(text))


def _sync_zenoh_log(timeout: float = 1.0) -> None:
    """Wait until the reader has handled every line Zenoh wrote so far (a marker
    written now comes out of the pipe after them)."""
    if not _routed.is_set():
        return
    with _synced:
        target = _sync_count + 1
    try:
        os.write(1, _SYNC)
    except OSError:
        return
    with _synced:
        _synced.wait_for(lambda: _sync_count >= target, timeout)


# --- session configuration ------------------------------------------------------

WAIT_BEFORE_CLOSE_US = 100_000
"""Zenoh's `wait_before_close` (microseconds) for router and clients."""
MAX_MESSAGE_BYTES = keys.IMAGE_MESSAGE_BYTES
"""Zenoh's `max_message_size`: nothing larger than the largest image we accept."""
CONNECT_TIMEOUT_S = 5.0
"""How long a probe waits for its router when no `--timeout` is given."""


def zenoh_config(
    *,
    mode: Literal["client", "peer", "router"] = "client",
    connect: list[str] | tuple[str, ...] = (),
    listen: list[str] | tuple[str, ...] = (),
    base_file: str | None = None,
    connect_timeout_s: float | None = None,
) -> zenoh.Config:
    """A Zenoh config with BuddyBot's rules: explicit endpoints, no multicast
    scouting, clients that wait for their router and reconnect quickly.

    `connect_timeout_s`: None (services) waits for the router forever;
    a number (probes) gives up after that long, so a tool never hangs."""
    config = read_zenoh_file(base_file) if base_file else zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    # A link that stays blocked this long is closed instead of holding back
    # every other stream behind one stalled reader (5 s by default; measured:
    # only this removed the radar gaps when one client was SIGSTOPped).
    config.insert_json5(
        "transport/link/tx/queue/congestion_control/block/wait_before_close",
        str(WAIT_BEFORE_CLOSE_US),
    )
    config.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE_BYTES))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if mode != "router":
        # Wait for the router forever (services start in any order) and retry
        # fast, so a router restart costs ~0.2 s instead of ~4 s.
        timeout_ms = -1 if connect_timeout_s is None else max(1, round(connect_timeout_s * 1000))
        config.insert_json5("connect/timeout_ms", str(timeout_ms))
        config.insert_json5("connect/retry", '{"period_init_ms": 100, "period_max_ms": 500}')
    return config


MAX_ZENOH_FILE_BYTES = 1 << 20
"""The largest Zenoh config file read (the deployment's router file is ~15 KB)."""


def read_zenoh_file(path: str) -> zenoh.Config:
    """A Zenoh config file, bounded before Zenoh parses it: its JSON5 parser
    recurses per level and a deeply nested file overflows the stack (SIGSEGV),
    so size and depth are checked first. ConfigError naming the file (exit
    status 2: the systemd units do not restart on it). YAML is Zenoh's own read."""
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_ZENOH_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the Zenoh config: {exc.strerror}") from None
    if len(data) > MAX_ZENOH_FILE_BYTES:
        raise ConfigError(f"{path}: not a valid Zenoh config: larger than "
                          f"{MAX_ZENOH_FILE_BYTES >> 20} MiB")
    try:
        check_depth(data, json5=True)
        if path.endswith((".yaml", ".yml")):
            return zenoh.Config.from_file(path)
        return zenoh.Config.from_json5(data.decode())
    except (TooDeep, UnicodeDecodeError, zenoh.ZError) as exc:
        raise ConfigError(f"{path}: not a valid Zenoh config: {exc}") from None


def open_router(listen: list[str], base_file: str | None = None, *,
                settle_s: float | None = None) -> zenoh.Session:
    """A Zenoh session in router mode listening on `listen`: what `buddybot router`
    serves, and what tests open in their own process. zenoh.ZError when Zenoh
    cannot open an endpoint.

    `settle_s`: how long opening waits once listening (Zenoh's `scouting/delay`,
    0.5 s unless `base_file` says otherwise); a router with nothing to find
    (a test's) need not wait at all."""
    config = zenoh_config(mode="router", listen=listen, base_file=base_file)
    if settle_s is not None:
        config.insert_json5("scouting/delay", str(max(0, round(settle_s * 1000))))
    return zenoh.open(config)


def open_session(
    config: zenoh.Config, stop: threading.Event, what: str = "router"
) -> zenoh.Session | None:
    """Open a session in a helper thread so the caller stays responsive to a
    stop request while Zenoh waits for the router. None when stopped first.

    A failure (a bounded connect timeout ran out) raises RouterUnreachable
    naming Zenoh's reason per endpoint (refused, TLS, ...) when Zenoh's log
    is routed (`route_zenoh_log`), else Zenoh's own error text. Zenoh failing
    to start for want of file descriptors (a flood of connections on the
    process's web server) is tried again every `RETRY_S` until it opens."""
    forget_connect_failures()
    waited = 0.0
    while True:
        result: dict[str, Any] = {}
        done = threading.Event()

        def opener(result: dict[str, Any] = result, done: threading.Event = done) -> None:
            try:
                result["session"] = zenoh.open(config)
            except BaseException as exc:  # ZError, or a Rust panic (a BaseException)
                result["error"] = exc
            done.set()

        threading.Thread(target=opener, name="zenoh-open", daemon=True).start()
        while not done.wait(0.1):
            if stop.is_set():
                return None
            waited += 0.1
            if abs(waited - 2.0) < 0.05 or (waited > 2 and int(waited * 10) % 100 == 0):
                why = _reasons_text(connect_failures())
                log.warning("waiting for the Zenoh %s (%.0f s so far)%s", what, waited,
                            f": {why}" if why else "")
        error = result.get("error")
        if error is None:
            session: zenoh.Session = result["session"]
            return session
        if not _out_of_resources(error):
            raise RouterUnreachable(_unreachable(what, error, _endpoints(config)))
        log.warning("Zenoh could not start (%s): out of file descriptors? again in %g s",
                    _clean(str(error)) or type(error).__name__, RETRY_S)
        if stop.wait(RETRY_S):
            return None
        waited += RETRY_S


RETRY_S = 1.0
"""How long `open_session` waits before trying again after Zenoh could not start."""


def _out_of_resources(error: BaseException) -> bool:
    """Zenoh could not start its runtime (no descriptor for a channel or a socket):
    a transient state of the process, not a fact about the router."""
    text = str(error)
    return "Too many open files" in text or "Failed to init" in text


def _reasons_text(reasons: dict[str, str]) -> str:
    if len(reasons) == 1:
        return next(iter(reasons.values()))
    return "; ".join(f"{endpoint}: {why}" for endpoint, why in reasons.items())


def _endpoints(config: zenoh.Config) -> list[str]:
    try:
        found = json.loads(config.get_json("connect/endpoints"))
    except (zenoh.ZError, ValueError):
        return []
    return [str(e) for e in found] if isinstance(found, list) else []


def _unreachable(what: str, error: BaseException, endpoints: list[str]) -> str:
    """One line: which endpoint(s), and why (Zenoh's reason per endpoint).

    Zenoh says nothing when a link opens but no session follows (`tls/` to a
    `tcp/` listener waits for a handshake that never comes): then a plain
    TCP connection tells "nothing listens" from "something else listens"."""
    text = _clean(str(error))
    if "Unable to connect to any of" not in text:  # Zenoh was specific (a TLS file, say)
        return f"no Zenoh {what}: {text}"
    _sync_zenoh_log()  # the reason lines were written before zenoh.open failed
    reasons = connect_failures()
    for endpoint in endpoints:
        if endpoint not in reasons:
            guess = _tcp_guess(endpoint)
            if guess:
                reasons[endpoint] = guess
    return f"no Zenoh {what}: {_reasons_text(reasons) or text}"


def _tcp_guess(endpoint: str) -> str | None:
    """What a TCP connection to a tcp/tls/ws endpoint's address says, if anything."""
    try:
        parsed = parse_endpoint(endpoint)
    except ValueError:
        return None
    if parsed.proto not in ("tcp", "tls", "ws"):
        return None
    try:
        with socket.create_connection((parsed.host, parsed.port), timeout=0.5):
            pass
    except OSError as exc:
        return exc.strerror or str(exc)
    return (f"a TCP connection opens at {parsed.address} but no Zenoh session follows "
            f"(wrong protocol, e.g. {parsed.proto}/ to a listener of another kind, "
            "or TLS settings?)")


def live_instances(session: zenoh.Session, key: str, timeout: float = 2.0) -> set[str]:
    """Instance ids of the liveliness tokens matching `key` (`.../nodes/<name>/*`)."""
    found: set[str] = set()
    for reply in session.liveliness().get(key, timeout=timeout):
        if reply.ok is None:
            continue
        parts = keys.split_absolute(str(reply.ok.key_expr))
        match = keys.NODES.match(parts[1]) if parts else None
        if match is not None:
            found.add(match["instance"])
    return found
