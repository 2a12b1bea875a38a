"""The supervisor: `buddybot up` (launching and restarting services), its
status line, and the embedded router. Built on the runtime."""
