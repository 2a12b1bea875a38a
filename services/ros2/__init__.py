"""ROS 2 interop: rmw_zenoh's wire format and our messages as ROS messages.

The `buddybot_interfaces` definitions (`ros2/buddybot_interfaces/`) are
generated from the contract by `interfaces`; `types` holds the ROS types
(standard and ours) with their RIHS01 hashes; `wire` the key expressions,
graph tokens and attachments of rmw_zenoh; `convert` our messages to and
from CDR payloads, with bounds (docs/ros2.md).
"""
