"""Checks a sensor's network URL before the bridge opens it.

pyserial reports a `socket://` or `rfc2217://` URL without a port, with a port
out of range or with an unknown option only when it opens it, and in words
that name none of that ("'<=' not supported between instances of 'int' and
'NoneType'"); the bridge would then retry a typo forever. A URL that can
never work is refused at start instead, naming what is wrong. Device paths
and other URL schemes are left to pyserial.
"""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

NETWORK_SCHEMES = {"socket": {"logging"}, "rfc2217": {"logging", "ign_set_control",
                                                      "poll_modem", "timeout"}}
"""URL schemes that name a host and port, with the options pyserial knows for each."""


def url_problem(url: str) -> str | None:
    """Why `url` can never be opened, or None (also for anything not a network URL)."""
    scheme, sep, _ = url.partition("://")
    options = NETWORK_SCHEMES.get(scheme.lower()) if sep else None
    if options is None:
        return None
    form = f"{scheme}://HOST:PORT"
    parts = urlsplit(url)
    if not parts.hostname:
        return f"no host: expected {form}"
    try:
        port = parts.port
    except ValueError:
        return f"port out of range (1..65535): expected {form}"
    if port is None or port == 0:
        return f"no port: expected {form} (the ESP32 stream server's port, e.g. 4001)"
    unknown = sorted(set(parse_qs(parts.query, keep_blank_values=True)) - options)
    if unknown:
        return f"unknown option {unknown[0]!r} (known: {', '.join(sorted(options))})"
    if parts.path not in ("", "/"):
        return f"unexpected path {parts.path!r}: expected {form}"
    return None
