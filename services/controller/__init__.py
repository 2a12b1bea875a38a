"""Controller: the robot's social behaviour."""
