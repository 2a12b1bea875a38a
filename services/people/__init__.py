"""People: who is near the robot, in which proxemic zone, and are they engaging.

The radar's presence and the camera's followed face are fused into persons
(one per visit, with an id never reused in a run), their Hall zone and their
engagement (NONE -> ENGAGING -> ENGAGED -> DISENGAGING -> GONE, ROS4HRI
style), so later behaviour can react to persons instead of raw sensor
states. This area holds the pure model only (`model.py`, `zones.py`,
`settings.py`); docs/people.md explains its rules.
"""
