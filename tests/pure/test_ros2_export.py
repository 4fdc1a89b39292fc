"""`swarm export RUN_DIR --ros2`: case 2 (2 s, in this process) as a rosbag2 (metadata.yaml and
an MCAP with ROS 2 encodings) read back by two readers that are not ours: `mcap` (schemas,
channels, message counts) and rosbags' AnyReader (types, counts, messages deserialized and
compared with trajectory.npz). Also: the start wall time, a gone agent, a bag replaced, and the
one line without rosbags (exit 2)."""

from __future__ import annotations

import json
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from typer.testing import CliRunner

import swarm
from swarm.cli.main import app
from swarm.contracts.vocabulary import ExitCode
from swarm.offline.ros2_export import INSTALL_HINT, ROS2_DIR, start_ns, write_ros2

ROOT = Path(__file__).resolve().parents[2]
CASE2 = ROOT / "scenarios" / "case2.toml"
DURATION = 2.0  # s: 200 ticks of case 2
TYPES = {"pose": "geometry_msgs/msg/PoseStamped", "odom": "nav_msgs/msg/Odometry", "cmd_vel": "geometry_msgs/msg/Twist"}
RIHS01 = {  # the hashes rmw_zenoh puts in its keys on Jazzy (REP-2016)
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "geometry_msgs/msg/Twist": "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
}


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def case2(tmp_path_factory) -> Path:
    """case 2 run for DURATION s, its directory written as `swarm sim` writes it."""
    out = tmp_path_factory.mktemp("case2") / "run"
    swarm.simulate(CASE2, duration=DURATION, out=out)
    return out


@pytest.fixture(scope="module")
def exported(case2) -> Path:
    res = invoke("export", case2, "--ros2", "--no-plots")
    assert res.exit_code == ExitCode.OK, res.output
    assert "ros2: ros2/ (ros2.mcap: " in res.output
    return case2 / ROS2_DIR


def expected_counts(run: Path) -> dict[str, int]:
    with np.load(run / "trajectory.npz") as z:
        rows, n = z["x"].shape
        ids, u = z["ids"], z["u"]
        counts = {}
        for j, aid in enumerate(ids):
            counts[f"/agent_{aid}/pose"] = rows
            counts[f"/agent_{aid}/odom"] = rows
            counts[f"/agent_{aid}/cmd_vel"] = int(np.isfinite(u[:, j]).sum())
    return counts


def yaw_of(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def angle_gap(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@pytest.mark.slow
def test_the_bag_directory_holds_metadata_and_one_mcap(exported):
    assert sorted(p.name for p in exported.iterdir()) == ["metadata.yaml", "ros2.mcap"]
    assert not list(exported.parent.glob(".ros2*"))  # no staging left behind
    meta = (exported / "metadata.yaml").read_text()
    assert "storage_identifier: mcap" in meta
    assert "ros2.mcap" in meta


def test_mcap_reads_ros2_schemas_channels_and_a_message_per_tick(exported, case2):
    with np.load(case2 / "trajectory.npz") as z:
        ticks = z["t"].shape[0] - 1
        ids = [int(a) for a in z["ids"]]
    assert ticks == round(DURATION / 0.01)
    with open(exported / "ros2.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.id: s for s in summary.schemas.values()}
        assert {s.name for s in schemas.values()} == set(TYPES.values())
        assert {s.encoding for s in schemas.values()} == {"ros2msg"}
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {f"/agent_{a}/{k}" for a in ids for k in TYPES}
        for topic, c in channels.items():
            assert c.message_encoding == "cdr"
            assert schemas[c.schema_id].name == TYPES[topic.rsplit("/", 1)[1]]
        counted = Counter(channel.topic for _, channel, _ in reader.iter_messages())
    stats = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counted == stats == expected_counts(case2)
    # a pose per row (ticks + the final state), a command per tick (the final row has none)
    assert set(counted.values()) == {ticks + 1, ticks}


def test_rosbags_reads_the_types_counts_and_the_poses_of_trajectory_npz(exported, case2):
    with np.load(case2 / "trajectory.npz") as z:
        t, x, y, h, u = (z[k] for k in ("t", "x", "y", "heading", "u"))
        ids, speed = [int(a) for a in z["ids"]], z["speed"]
    store = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([exported], default_typestore=store) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {f"/agent_{a}/{k}": v for a in ids for k, v in TYPES.items()}
        assert {c.topic: c.msgcount for c in reader.connections} == expected_counts(case2)
        assert {c.digest for c in reader.connections} == set(RIHS01.values())
        for c in reader.connections:
            assert store.hash_rihs01(c.msgtype) == RIHS01[c.msgtype]
        rows = {topic: 0 for topic in types}
        for conn, stamp, raw in reader.messages():
            j = ids.index(int(conn.topic.split("/")[1].removeprefix("agent_")))
            k = rows[conn.topic]
            rows[conn.topic] += 1
            if k % 37 and k != t.shape[0] - 1:  # the first, every 37th and the last row
                continue
            assert stamp == round(t[k] * 1e9)
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == TYPES["cmd_vel"]:
                assert msg.linear.x == speed[j]
                assert msg.angular.z == u[k, j]
                continue
            pose = msg.pose if conn.msgtype == TYPES["pose"] else msg.pose.pose
            assert msg.header.frame_id == "world"
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamp
            assert abs(pose.position.x - x[k, j]) < 1e-9
            assert abs(pose.position.y - y[k, j]) < 1e-9
            assert pose.position.z == 0.0
            assert angle_gap(yaw_of(pose.orientation), h[k, j]) < 1e-9
            assert abs(math.hypot(pose.orientation.z, pose.orientation.w) - 1.0) < 1e-12
            if conn.msgtype == TYPES["odom"]:
                assert msg.child_frame_id == f"agent_{ids[j]}/base_footprint"
                moving = np.isfinite(u[k, j])
                assert msg.twist.twist.linear.x == (speed[j] if moving else 0.0)
                assert msg.twist.twist.angular.z == (u[k, j] if moving else 0.0)
        assert rows == expected_counts(case2)


@pytest.mark.slow
def test_the_stamps_start_at_the_summarys_start_wall_time(case2, tmp_path):
    assert start_ns({}) == 0
    assert start_ns({"start_wall_time": 1764144000.25}) == 1764144000_250000000
    assert start_ns({"start_wall_time": "yesterday"}) == 0
    run = swarm.open_run(case2)
    summary = dict(json.loads((case2 / "summary.json").read_text()), start_wall_time=1764144000.5)
    bag = write_ros2(tmp_path, run.arrays, summary)
    with AnyReader([bag.path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        first = next(reader.messages())
        assert first[1] == 1764144000_500000000
        assert reader.start_time == 1764144000_500000000
        assert reader.end_time - reader.start_time == pytest.approx(DURATION * 1e9, abs=1)


def test_a_gone_agent_has_no_pose_and_no_command_while_gone(case2, tmp_path):
    run = swarm.open_run(case2)
    arrays = {k: np.array(v, copy=True) for k, v in run.arrays.items()}
    j = 2
    arrays["alive"][50:, j] = False
    arrays["u"][50:, j] = np.nan
    bag = write_ros2(tmp_path, arrays, {})
    aid = int(arrays["ids"][j])
    assert bag.counts[f"/agent_{aid}/pose"] == bag.counts[f"/agent_{aid}/odom"] == 50
    assert bag.counts[f"/agent_{aid}/cmd_vel"] == 50
    rows = arrays["t"].shape[0]
    other = int(arrays["ids"][0])
    assert bag.counts[f"/agent_{other}/pose"] == rows
    assert bag.counts[f"/agent_{other}/cmd_vel"] == rows - 1


@pytest.mark.slow
def test_exporting_again_replaces_the_bag(exported, case2):
    before = (exported / "ros2.mcap").stat().st_mtime_ns
    (exported / "stray.txt").write_text("from an earlier bag")
    res = invoke("export", case2, "--ros2", "--no-plots")
    assert res.exit_code == ExitCode.OK, res.output
    assert sorted(p.name for p in exported.iterdir()) == ["metadata.yaml", "ros2.mcap"]
    assert (exported / "ros2.mcap").stat().st_mtime_ns >= before


def test_without_rosbags_one_line_says_how_to_install_it_exit_2(case2, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags", None)  # importlib finds no spec: as if not installed
    res = invoke("export", case2, "--ros2", "--no-plots")
    assert res.exit_code == ExitCode.USAGE
    assert res.output.strip() == INSTALL_HINT
    assert "pip install -e '.[ros2]'" in INSTALL_HINT and "swarm-circumnav[ros2]" in INSTALL_HINT
