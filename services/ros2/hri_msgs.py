"""The two `hri_msgs` types the bridge publishes, as `.msg` text (REP-155, ROS4HRI).

No `hri_msgs` package ships for the store the bridge uses, so the two
definitions it needs are written here from REP-155 and the released
ROS 2 `hri_msgs` (2.x: a `std_msgs/Header`, not the later `IdHeader`);
`types.build_typestore` registers them, and their RIHS01 hashes come out
as for any other type (tests/ros2/test_hri.py pins them).
"""

from __future__ import annotations

PACKAGE = "hri_msgs"
IDS_LIST = f"{PACKAGE}/msg/IdsList"
ENGAGEMENT_LEVEL = f"{PACKAGE}/msg/EngagementLevel"

DEFINITIONS: dict[str, str] = {
    IDS_LIST: "std_msgs/Header header\nstring[] ids\n",
    ENGAGEMENT_LEVEL: (
        "std_msgs/Header header\n"
        "uint8 UNKNOWN=0\nuint8 DISENGAGED=1\nuint8 ENGAGING=2\nuint8 ENGAGED=3\n"
        "uint8 DISENGAGING=4\n"
        "uint8 level\n"),
}
"""Type name -> its `.msg` text: the ids tracked now, and one person's engagement."""
