"""`python -m buddybot` is the `buddybot` command."""

import sys

from buddybot.cli import main

sys.exit(main())
