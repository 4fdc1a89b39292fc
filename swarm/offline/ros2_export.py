"""`swarm export RUN_DIR --ros2`: a run as a rosbag2 directory, RUN_DIR/ros2/ (metadata.yaml and
one MCAP file with ROS 2 message encodings: CDR payloads, ros2msg schemas, zstd chunks), which
`ros2 bag info/play` and Foxglove open with ROS types. Per agent (docs/reference/outputs.md has
the files of a run; docs/guides/robots.md the robot runs):

    /agent_<id>/pose     geometry_msgs/msg/PoseStamped  the pose (x, y, heading) in frame "world"
    /agent_<id>/odom     nav_msgs/msg/Odometry          the same pose; twist linear.x = the agent's
                                                        speed, angular.z = its turn rate u (a zero
                                                        twist on a row without a command)
    /agent_<id>/cmd_vel  geometry_msgs/msg/Twist        the recorded command: linear.x = speed,
                                                        angular.z = u

A pose is written for every row of trajectory.npz where the agent is alive with a finite pose; a
command for every row with a finite u (none on the final row, which records the state after the
last tick, and none while the agent is gone). A row's time stamp is the run's start (the
summary's `start_wall_time`, unix s, when present; else 0) plus its time t = tick * dt.

rosbags (the `ros2` extra) writes the bag; it is imported only here, when a bag is written.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.vocabulary import Coded, ExitCode

ROS2_DIR = "ros2"
WORLD_FRAME = "world"
DISTRO_STORE = "ROS2_JAZZY"  # the message definitions (and RIHS01 hashes) written into the bag
START_KEYS = ("start_wall_time", "started_at")  # the summary's run start, unix seconds, if it has one
INSTALL_HINT = (
    "swarm export --ros2 needs rosbags: pip install -e '.[ros2]' in the clone "
    "(the distribution swarm-circumnav[ros2]), or pip install 'rosbags>=0.11,<0.12'"
)

POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
TWIST = "geometry_msgs/msg/Twist"


class Ros2ExportError(Coded):
    """The bag cannot be written (rosbags missing: exit 2; a run without poses or an OS error: exit 1)."""

    exit_code = ExitCode.FAILED


class RosbagsMissing(Ros2ExportError):
    exit_code = ExitCode.USAGE


def rosbags_available() -> bool:
    """Whether rosbags (the `ros2` extra) is installed."""
    return importlib.util.find_spec("rosbags") is not None


def topics_of(agent_id: int) -> dict[str, str]:
    """An agent's topics -> their ROS 2 types."""
    ns = f"/agent_{agent_id}"
    return {f"{ns}/pose": POSE_STAMPED, f"{ns}/odom": ODOMETRY, f"{ns}/cmd_vel": TWIST}


def start_ns(summary: Mapping[str, Any]) -> int:
    """The run's start in ns since the epoch (the summary's start wall time; 0 without one)."""
    for key in START_KEYS:
        value = summary.get(key)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0:
            return int(Decimal(repr(value)) * 1_000_000_000)  # value * 1e9 would be off by up to 256 ns
    return 0


def headings(arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    """(T, N) headings: trajectory.npz's `heading`, or (a run written before it was recorded)
    the direction of motion from one row to the next (the last row repeats the one before)."""
    heading = arrays.get("heading")
    if heading is not None:
        return np.asarray(heading, dtype=float)
    x, y = np.asarray(arrays["x"], dtype=float), np.asarray(arrays["y"], dtype=float)
    h = np.full(x.shape, np.nan)
    if x.shape[0] > 1:
        h[:-1] = np.arctan2(np.diff(y, axis=0), np.diff(x, axis=0))
        h[-1] = h[-2]
    return h


@dataclass(frozen=True)
class Ros2Export:
    """What `write_ros2` wrote: the bag directory, its MCAP file, and per topic its type and
    message count."""

    path: Path
    mcap: Path
    types: dict[str, str]
    counts: dict[str, int]

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    def line(self) -> str:
        n = len(self.types) // 3
        return (
            f"ros2: {self.path.name}/ ({self.mcap.name}: {self.messages} messages on {len(self.types)} topics, "
            f"PoseStamped, Odometry and Twist for {n} agent{'s' if n != 1 else ''})"
        )


def write_ros2(run_dir: Path, arrays: Mapping[str, np.ndarray], summary: Mapping[str, Any]) -> Ros2Export:
    """Write RUN_DIR/ros2/ from a run's arrays (trajectory.npz's, by name) and summary; a bag
    already there is replaced (the new one is written beside it, then moved in). Raises
    RosbagsMissing without rosbags, Ros2ExportError when it cannot be written."""
    if not rosbags_available():
        raise RosbagsMissing(INSTALL_HINT)
    run_dir = Path(run_dir)
    final = run_dir / ROS2_DIR
    staging = run_dir / f".{ROS2_DIR}.tmp"  # the bag is written as staging/ros2 (its MCAP: ros2.mcap)
    shutil.rmtree(staging, ignore_errors=True)
    try:
        counts, types = _write_bag(staging / ROS2_DIR, arrays, summary)
        if final.is_dir() and not final.is_symlink():
            shutil.rmtree(final)
        elif final.exists() or final.is_symlink():
            final.unlink()
        (staging / ROS2_DIR).rename(final)
    except OSError as e:
        raise Ros2ExportError(f"{final}: cannot write: {e.strerror or e}") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    mcaps = sorted(final.glob("*.mcap"))
    return Ros2Export(final, mcaps[0] if mcaps else final, types, counts)


def _write_bag(
    path: Path, arrays: Mapping[str, np.ndarray], summary: Mapping[str, Any]
) -> tuple[dict[str, int], dict[str, str]]:
    # lazy: rosbags is the optional `ros2` extra (and ~0.2 s to import), needed only for this bag
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores[DISTRO_STORE])
    T = store.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Point, Quaternion, Pose = (
        T["geometry_msgs/msg/Point"],
        T["geometry_msgs/msg/Quaternion"],
        T["geometry_msgs/msg/Pose"],
    )
    Vector3, Twist = T["geometry_msgs/msg/Vector3"], T[TWIST]
    PoseStamped, Odometry = T[POSE_STAMPED], T[ODOMETRY]
    PoseCov, TwistCov = T["geometry_msgs/msg/PoseWithCovariance"], T["geometry_msgs/msg/TwistWithCovariance"]
    zero_cov = np.zeros(36, dtype=np.float64)
    zero = Vector3(x=0.0, y=0.0, z=0.0)
    still = Twist(linear=zero, angular=zero)

    ids = np.asarray(arrays["ids"]).reshape(-1)
    t = np.asarray(arrays["t"], dtype=float).reshape(-1)
    x, y = np.asarray(arrays["x"], dtype=float), np.asarray(arrays["y"], dtype=float)
    u = np.asarray(arrays["u"], dtype=float)
    heading = headings(arrays)
    alive = np.asarray(arrays["alive"], dtype=bool)
    speeds = arrays.get("speed")
    speed = np.zeros(len(ids)) if speeds is None else np.asarray(speeds, dtype=float).reshape(-1)
    t0 = start_ns(summary)
    stamps = [t0 + round(float(tk) * 1e9) for tk in t]

    writer = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    for key in ("scenario", "engine"):
        if isinstance(summary.get(key), str):
            writer.set_custom_data(f"swarm.{key}", summary[key])
    counts: dict[str, int] = {}
    types: dict[str, str] = {}
    with writer:
        for j, aid in enumerate(int(a) for a in ids):
            topics = topics_of(aid)
            types.update(topics)
            pose_topic, odom_topic, cmd_topic = topics
            conns = {name: writer.add_connection(name, kind, typestore=store) for name, kind in topics.items()}
            counts.update(dict.fromkeys(topics, 0))
            child = f"agent_{aid}/base_footprint"
            v = float(speed[j])
            has_pose = alive[:, j] & np.isfinite(x[:, j]) & np.isfinite(y[:, j]) & np.isfinite(heading[:, j])
            has_cmd = alive[:, j] & np.isfinite(u[:, j])
            for k in range(len(t)):
                stamp = stamps[k]
                cmd = (
                    Twist(linear=Vector3(x=v, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=float(u[k, j])))
                    if has_cmd[k]
                    else None
                )
                if has_pose[k]:
                    half = 0.5 * float(heading[k, j])
                    pose = Pose(
                        position=Point(x=float(x[k, j]), y=float(y[k, j]), z=0.0),
                        orientation=Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
                    )
                    header = Header(
                        stamp=Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000), frame_id=WORLD_FRAME
                    )
                    ps = PoseStamped(header=header, pose=pose)
                    writer.write(conns[pose_topic], stamp, store.serialize_cdr(ps, POSE_STAMPED))
                    odom = Odometry(
                        header=header,
                        child_frame_id=child,
                        pose=PoseCov(pose=pose, covariance=zero_cov),
                        twist=TwistCov(twist=cmd if cmd is not None else still, covariance=zero_cov),
                    )
                    writer.write(conns[odom_topic], stamp, store.serialize_cdr(odom, ODOMETRY))
                    counts[pose_topic] += 1
                    counts[odom_topic] += 1
                if cmd is not None:
                    writer.write(conns[cmd_topic], stamp, store.serialize_cdr(cmd, TWIST))
                    counts[cmd_topic] += 1
    if not any(counts.values()):
        raise Ros2ExportError(f"{path.parent.parent}: no agent has a pose in this run; no bag written")
    return counts, types


__all__ = [
    "ROS2_DIR",
    "WORLD_FRAME",
    "INSTALL_HINT",
    "Ros2Export",
    "Ros2ExportError",
    "RosbagsMissing",
    "rosbags_available",
    "start_ns",
    "topics_of",
    "write_ros2",
]
