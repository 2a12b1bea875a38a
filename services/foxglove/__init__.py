"""Foxglove bridge: every key of the robot live in the Foxglove app (docs/foxglove.md)."""
