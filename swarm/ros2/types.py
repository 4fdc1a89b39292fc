"""The ROS 2 message types the robots speak, with the names and type hashes rmw_zenoh puts in
its keys and liveliness tokens.

The RIHS01 hashes (REP 2016) are those rosbags' `Typestore.hash_rihs01` computes, identical in
its Humble and Jazzy stores (tests/pure/test_ros2_wire.py checks them). rmw_zenoh on Humble writes
the literal `TypeHashNotSupported` instead, so a Humble and a Jazzy node never meet on a topic.
"""

from __future__ import annotations

from dataclasses import dataclass

HUMBLE_HASH = "TypeHashNotSupported"  # what Humble's rmw_zenoh writes in place of a type hash
DISTROS = ("humble", "jazzy", "kilted", "rolling")  # the ROS 2 distributions rmw_zenoh is released for


@dataclass(frozen=True)
class RosType:
    name: str  # "geometry_msgs/msg/Twist"
    dds: str  # "geometry_msgs::msg::dds_::Twist_"
    rihs01: str  # "RIHS01_" + 64 lowercase hex

    @property
    def short(self) -> str:
        """The type's own name: "Twist"."""
        return self.name.rsplit("/", 1)[-1]

    def hash_for(self, distro: str) -> str:
        """The type hash rmw_zenoh of `distro` writes: RIHS01 from Jazzy on, Humble none."""
        if distro not in DISTROS:
            raise ValueError(f"unknown ROS 2 distribution {distro!r} (one of {', '.join(DISTROS)})")
        return HUMBLE_HASH if distro == "humble" else self.rihs01


def dds_name(name: str) -> str:
    """ "geometry_msgs/msg/Twist" -> "geometry_msgs::msg::dds_::Twist_"."""
    pkg, kind, base = name.split("/")
    return f"{pkg}::{kind}::dds_::{base}_"


def _type(name: str, rihs01: str) -> RosType:
    return RosType(name, dds_name(name), rihs01)


TWIST = _type("geometry_msgs/msg/Twist", "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
TWIST_STAMPED = _type(
    "geometry_msgs/msg/TwistStamped", "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
)
ODOMETRY = _type("nav_msgs/msg/Odometry", "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0")
POSE_STAMPED = _type(
    "geometry_msgs/msg/PoseStamped", "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
)
TYPES = (TWIST, TWIST_STAMPED, ODOMETRY, POSE_STAMPED)

# Each type by its short name, its full name and its DDS name.
BY_NAME: dict[str, RosType] = {key: t for t in TYPES for key in (t.short, t.name, t.dds)}
