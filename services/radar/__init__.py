"""Radar: LD2410 protocol, the radar bridge, a simulated sensor and presence detection."""
