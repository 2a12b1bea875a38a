"""`python -m buddybot` is the `buddybot` command."""

from buddybot.cli import run_and_exit

run_and_exit()
