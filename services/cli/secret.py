"""`buddybot secret show|rotate|revoke [ROLE]`: the web surfaces' per-robot secrets.

`show` prints the secret (made now if there is none yet, as the first start
would); `rotate` replaces it, ending every session it signed; `revoke`
empties it: no one of that role logs in until the next `rotate`. The
running dashboard and Foxglove bridge notice the change at once (they
re-read the file when it changes). Files: `buddybot.web.auth`.
"""

from __future__ import annotations

import argparse
import sys

from buddybot.runtime.service import ServiceContext
from buddybot.web import auth as web_auth

HELP = "show, rotate or revoke the dashboard/Foxglove secrets"
USES_CONFIG = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=("show", "rotate", "revoke"))
    parser.add_argument("role", nargs="?", default="operator", choices=web_auth.ROLES,
                        help="operator (watch and press buttons, the default), viewer "
                        "(watch only) or foxglove (the Foxglove bridge's token)")


def main(ctx: ServiceContext) -> int:
    role: str = ctx.args.role
    path = web_auth.secret_path(role)
    try:
        if ctx.args.action == "show":
            web_auth.ensure_secret(path)
            value = web_auth.read_secret(path)
            if value is None:
                print(f"{role}: revoked ({path}); `buddybot secret rotate {role}` makes a new one",
                      file=sys.stderr)
                return 1
            print(value)
        elif ctx.args.action == "rotate":
            web_auth.write_secret(path, web_auth.new_secret())
            print(f"{role}: new secret in {path}; every {role} session has ended",
                  file=sys.stderr)
        else:
            web_auth.write_secret(path, "")
            print(f"{role}: revoked ({path}); every {role} session has ended", file=sys.stderr)
    except (web_auth.SecretError, OSError) as exc:
        print(f"secret {ctx.args.action}: {exc}", file=sys.stderr)
        return 1
    return 0
