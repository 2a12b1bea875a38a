"""`buddybot.sdk`: a library for builders' Python programs on a running robot.

`Bot.connect()` joins the robot's router like every tool does (same config
resolution, bounded connect); `bot.people`, `bot.on`/`bot.events`/
`bot.wait_for`, `bot.lease`, `bot.eyes`, `bot.play`/`bot.say` and
`bot.params` sit on the runtime's node, handles, keys and messages only.
docs/sdk.md is the reference.
"""

from buddybot.sdk.bot import Bot, add_arguments
from buddybot.sdk.errors import NoRouter, NoService, Refused, SdkError, TimedOut
from buddybot.sdk.eyes import ALIASES, Eyes, EyesHandle
from buddybot.sdk.identity import KnownPerson
from buddybot.sdk.leases import Lease
from buddybot.sdk.people import Event, EventStream, Person
from buddybot.sdk.speaker import SoundHandle

__all__ = ["ALIASES", "Bot", "Event", "EventStream", "Eyes", "EyesHandle", "KnownPerson", "Lease",
           "NoRouter", "NoService", "Person", "Refused", "SdkError", "SoundHandle",
           "TimedOut", "add_arguments"]
