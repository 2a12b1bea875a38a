"""People: who is near the robot, in which proxemic zone, and are they engaging.

The radar's presence and the camera's followed face are fused into persons
(one per visit, with an id never reused in a run), their Hall zone and their
engagement (NONE -> ENGAGING -> ENGAGED -> DISENGAGING -> GONE, ROS4HRI
style), so later behaviour can react to persons instead of raw sensor
states. The pure model is `model.py` and `zones.py`, its `[people]` table
`settings.py`, and `service.py` (`buddybot run people`) publishes its
events and persons; docs/people.md explains the rules.
"""
