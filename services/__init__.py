"""BuddyBot: the software of a desktop social robot, one process per driver on Eclipse Zenoh."""

__version__ = "0.1.0"
