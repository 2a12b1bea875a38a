"""The dashboard: a live web page of what the robot perceives (docs/dashboard.md)."""
