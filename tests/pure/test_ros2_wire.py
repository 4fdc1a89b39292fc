"""swarm.ros2's bytes against known values: rosbags' RIHS01 hashes and CDR (both ways), the keys,
tokens and attachment observed from zenoh-ros2-sdk on a live zenoh 1.10 router and documented
by rmw_zenoh's design.md, and malformed payloads failing with CdrError only."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore

from swarm.ros2 import cdr
from swarm.ros2.attachment import attachment, gid_for, parse_attachment
from swarm.ros2.keys import (
    EntityInfo,
    QoS,
    entity_token,
    mangle,
    node_token,
    parse_entity_token,
    resolve,
    topic_key,
)
from swarm.ros2.types import BY_NAME, ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED, TYPES, RosType

JAZZY = get_typestore(Stores.ROS2_JAZZY)
HUMBLE = get_typestore(Stores.ROS2_HUMBLE)
T = JAZZY.types
NS = 1_000_000_000

# What zenoh-ros2-sdk put on a live router (FINDINGS: observe.log) and rmw_zenoh's design.md.
ZID = "a119feee36fd524180c3159814176ecc"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
OBSERVED_KEY = f"0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}"
OBSERVED_NN = f"@ros2_lv/0/{ZID}/0/0/NN/%/%/sdk_listener"
OBSERVED_MS = (
    "@ros2_lv/0/a119feee36fd524180c3159814176ecc/0/0/MS/%/%/sdk_listener/%robot1%cmd_vel/geometry_msgs::msg::dds_::"
    "Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a/::,10:,:,:,,"
)
OBSERVED_NN_NS = f"@ros2_lv/0/{ZID}/1/1/NN/%/%robot1/sdk_teleop"
OBSERVED_MP = (
    "@ros2_lv/0/a119feee36fd524180c3159814176ecc/1/1/MP/%/%robot1/sdk_teleop/%robot1%cmd_vel/geometry_msgs::msg::dds_::"
    "Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a/::,10:,:,:,,"
)
OBSERVED_ATTACHMENT = bytes.fromhex("000000000000000000a21a99e788eb18105fa26d14ccd447c29299b33564eee8c9")
OBSERVED_TWIST = bytes.fromhex(
    "00010000295c8fc2f528cc3f0000000000000000000000000000000000000000000000000000000000000000000000000000e03f"
)

# ---------------------------------------------------------------- types and hashes


@pytest.mark.parametrize("store", [JAZZY, HUMBLE], ids=["jazzy", "humble"])
@pytest.mark.parametrize("rtype", TYPES, ids=lambda t: t.short)
def test_rihs01_hashes_are_rosbags(store, rtype):
    assert store.hash_rihs01(rtype.name) == rtype.rihs01


def test_hash_constants_are_the_known_values():
    assert TWIST.rihs01 == TWIST_HASH
    assert TWIST_STAMPED.rihs01 == "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
    assert ODOMETRY.rihs01 == "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    assert POSE_STAMPED.rihs01 == "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"


def test_hash_per_distro():
    for t in TYPES:
        assert t.hash_for("jazzy") == t.hash_for("kilted") == t.hash_for("rolling") == t.rihs01
        assert t.hash_for("humble") == "TypeHashNotSupported"
    with pytest.raises(ValueError):
        TWIST.hash_for("foxy")


def test_dds_names_and_lookup():
    assert [t.dds for t in TYPES] == [
        "geometry_msgs::msg::dds_::Twist_",
        "geometry_msgs::msg::dds_::TwistStamped_",
        "nav_msgs::msg::dds_::Odometry_",
        "geometry_msgs::msg::dds_::PoseStamped_",
    ]
    for t in TYPES:
        assert BY_NAME[t.short] is BY_NAME[t.name] is BY_NAME[t.dds] is t
    assert len(BY_NAME) == 12


# ---------------------------------------------------------------- CDR: known bytes


def test_twist_bytes_are_the_observed_ones():
    assert cdr.encode_twist(0.22, 0.5) == OBSERVED_TWIST
    assert cdr.decode_twist(OBSERVED_TWIST) == (0.22, 0.5)


def test_twist_stamped_bytes():
    want = bytes.fromhex(
        "0001000001000000020000000a000000626173655f6c696e6b000000295c8fc2f528cc3f" + "00" * 32 + "000000000000e03f"
    )
    assert len(want) == 76
    got = cdr.encode_twist_stamped(1 * NS + 2, "base_link", 0.22, 0.5)
    assert got == want
    assert cdr.decode_twist_stamped(want) == (1 * NS + 2, "base_link", 0.22, 0.5)


def test_odometry_and_pose_stamped_sizes():
    assert len(cdr.encode_odometry(0, "odom", "base_footprint", 1.0, 2.0, 0.3)) == 724
    assert (
        len(cdr.encode_pose_stamped(0, "world", 1.0, 2.0, 0.3)) == 4 + 8 + 4 + 6 + 6 + 7 * 8
    )  # header, stamp, length, 'world\0', pad to 8, pose


def test_negative_stamp_is_a_ros_time():
    sec, nanosec = struct.unpack_from("<iI", cdr.encode_twist_stamped(-1, "", 0.0, 0.0), 4)
    assert (sec, nanosec) == (-1, NS - 1)
    with pytest.raises(ValueError):
        cdr.encode_twist_stamped(2**31 * NS, "", 0.0, 0.0)
    with pytest.raises(ValueError):
        cdr.encode_twist_stamped(0, "a\0b", 0.0, 0.0)


# ---------------------------------------------------------------- CDR: against rosbags, both ways

floats = st.floats(allow_nan=False, width=64)
finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9)
frames = st.text(st.characters(codec="utf-8", exclude_characters="\0"), max_size=40)
stamps = st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, NS - 1))
yaws = st.floats(-math.pi, math.pi)


def _vec(x=0.0, y=0.0, z=0.0):
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def _twist(vx, wz, vy=0.0, vz=0.0, wx=0.0, wy=0.0):
    return T["geometry_msgs/msg/Twist"](linear=_vec(vx, vy, vz), angular=_vec(wx, wy, wz))


def _header(stamp, frame):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1]), frame_id=frame
    )


def _pose(x, y, qx, qy, qz, qw, z=0.0):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
    )


def _ser(msg, rtype: RosType) -> bytes:
    return bytes(JAZZY.serialize_cdr(msg, rtype.name))


def _ns(stamp) -> int:
    return stamp[0] * NS + stamp[1]


@settings(max_examples=60, deadline=None)
@given(floats, floats, floats)
def test_twist_matches_rosbags(vx, wz, other):
    ours = cdr.encode_twist(vx, wz)
    assert ours == _ser(_twist(vx, wz), TWIST)
    back = JAZZY.deserialize_cdr(ours, TWIST.name)
    assert (back.linear.x, back.angular.z, back.linear.y) == (vx, wz, 0.0)
    assert cdr.decode_twist(_ser(_twist(vx, wz, vy=other, wx=other), TWIST)) == (vx, wz)


@settings(max_examples=60, deadline=None)
@given(stamps, frames, floats, floats, floats)
def test_twist_stamped_matches_rosbags(stamp, frame, vx, wz, other):
    ours = cdr.encode_twist_stamped(_ns(stamp), frame, vx, wz)
    msg = T["geometry_msgs/msg/TwistStamped"](header=_header(stamp, frame), twist=_twist(vx, wz))
    assert ours == _ser(msg, TWIST_STAMPED)
    back = JAZZY.deserialize_cdr(ours, TWIST_STAMPED.name)
    assert (back.header.stamp.sec, back.header.stamp.nanosec, back.header.frame_id) == (stamp[0], stamp[1], frame)
    assert (back.twist.linear.x, back.twist.angular.z) == (vx, wz)
    theirs = _ser(
        T["geometry_msgs/msg/TwistStamped"](header=_header(stamp, frame), twist=_twist(vx, wz, vz=other)), TWIST_STAMPED
    )
    assert cdr.decode_twist_stamped(theirs) == (_ns(stamp), frame, vx, wz)


def _odometry(stamp, frame, child, pose, twist, cov=0.0):
    c = np.full(36, cov, dtype=np.float64)
    return T["nav_msgs/msg/Odometry"](
        header=_header(stamp, frame),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=c),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=c.copy()),
    )


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(stamps, frames, frames, finite, finite, yaws, floats, floats)
def test_odometry_matches_rosbags(stamp, frame, child, x, y, yaw, vx, wz):
    ours = cdr.encode_odometry(_ns(stamp), frame, child, x, y, yaw, vx, wz)
    qz, qw = math.sin(yaw / 2), math.cos(yaw / 2)
    msg = _odometry(stamp, frame, child, _pose(x, y, 0.0, 0.0, qz, qw), _twist(vx, wz))
    assert ours == _ser(msg, ODOMETRY)
    back = JAZZY.deserialize_cdr(ours, ODOMETRY.name)
    assert back.child_frame_id == child and back.pose.pose.position.x == x
    assert (back.twist.twist.linear.x, back.twist.twist.angular.z) == (vx, wz)
    got = cdr.decode_odometry(ours)
    assert (got.stamp_ns, got.frame_id, got.x, got.y) == (_ns(stamp), frame, x, y)
    assert math.isclose(math.remainder(got.yaw - yaw, math.tau), 0.0, abs_tol=1e-12)


@settings(max_examples=60, deadline=None)
@given(stamps, frames, finite, finite, finite, yaws)
def test_decode_odometry_of_rosbags(stamp, frame, x, y, z, yaw):
    """Their bytes, with a height, covariances and a twist we ignore."""
    msg = _odometry(
        stamp,
        frame,
        "base_footprint",
        _pose(x, y, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2), z=z),
        _twist(1, 2, 3),
        cov=7.5,
    )
    got = cdr.decode_odometry(_ser(msg, ODOMETRY))
    assert (got.stamp_ns, got.frame_id, got.x, got.y) == (_ns(stamp), frame, x, y)
    assert math.isclose(math.remainder(got.yaw - yaw, math.tau), 0.0, abs_tol=1e-12)


@settings(max_examples=60, deadline=None)
@given(stamps, frames, finite, finite, yaws)
def test_pose_stamped_matches_rosbags(stamp, frame, x, y, yaw):
    ours = cdr.encode_pose_stamped(_ns(stamp), frame, x, y, yaw)
    msg = T["geometry_msgs/msg/PoseStamped"](
        header=_header(stamp, frame), pose=_pose(x, y, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    )
    assert ours == _ser(msg, POSE_STAMPED)
    back = JAZZY.deserialize_cdr(ours, POSE_STAMPED.name)
    assert (back.header.frame_id, back.pose.position.x, back.pose.position.y) == (frame, x, y)
    got = cdr.decode_pose_stamped(_ser(msg, POSE_STAMPED))
    assert (got.stamp_ns, got.frame_id, got.x, got.y) == (_ns(stamp), frame, x, y)
    assert math.isclose(math.remainder(got.yaw - yaw, math.tau), 0.0, abs_tol=1e-12)


def test_yaw_of_a_tilted_quaternion():
    """A quaternion with roll and pitch: yaw is the heading (ZYX Euler), as tf2 gives it."""
    roll, pitch, yaw = 0.2, -0.1, 2.5
    cr, sr, cp, sp, cy, sy = (f(a / 2) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    q = (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )
    msg = T["geometry_msgs/msg/PoseStamped"](header=_header((1, 0), "world"), pose=_pose(1.0, 2.0, *q))
    assert math.isclose(cdr.decode_pose_stamped(_ser(msg, POSE_STAMPED)).yaw, yaw, abs_tol=1e-12)


# ---------------------------------------------------------------- CDR: malformed

DECODERS = [cdr.decode_twist, cdr.decode_twist_stamped, cdr.decode_odometry, cdr.decode_pose_stamped]
VALID = [
    cdr.encode_twist(0.1, 0.2),
    cdr.encode_twist_stamped(5, "base_link", 0.1, 0.2),
    cdr.encode_odometry(5, "odom", "base_footprint", 1, 2, 0.3, 0.1, 0.2),
    cdr.encode_pose_stamped(5, "world", 1, 2, 0.3),
]


@pytest.mark.parametrize(
    "decode,valid", list(zip(DECODERS, VALID, strict=True)), ids=lambda v: getattr(v, "__name__", "")
)
def test_every_short_payload_is_a_cdr_error(decode, valid):
    decode(valid)
    for n in range(len(valid)):
        with pytest.raises(cdr.CdrError):
            decode(valid[:n])


@pytest.mark.parametrize(
    "decode,valid", list(zip(DECODERS, VALID, strict=True)), ids=lambda v: getattr(v, "__name__", "")
)
def test_wrong_header_is_a_cdr_error(decode, valid):
    for head in (b"\x00\x00\x00\x00", b"\x01\x00\x00\x00", b"\x00\x03\x00\x00", b"\xff\xff\xff\xff"):
        with pytest.raises(cdr.CdrError, match="encapsulation"):
            decode(head + valid[4:])


@pytest.mark.parametrize("decode", DECODERS[1:], ids=lambda d: d.__name__)
def test_bad_strings_are_cdr_errors(decode):
    stamp = struct.pack("<iI", 1, 2)
    tail = b"\0" * 800
    for bad in (
        struct.pack("<I", 0xFFFFFFFF) + b"abc\0" + tail,  # huge length
        struct.pack("<I", 4) + b"abcd" + tail,  # no NUL
        struct.pack("<I", 3) + b"\xff\xfe\0" + tail,  # not UTF-8
    ):
        with pytest.raises(cdr.CdrError):
            decode(cdr.HEADER + stamp + bad)
    with pytest.raises(cdr.CdrError, match="nanosec"):
        decode(cdr.HEADER + struct.pack("<iI", 1, NS) + struct.pack("<I", 1) + b"\0" + tail)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=900), st.booleans())
def test_random_bytes_raise_only_cdr_error(data, with_header):
    payload = cdr.HEADER + data if with_header else data
    for decode in DECODERS:
        try:
            decode(payload)
        except cdr.CdrError:
            pass


# ---------------------------------------------------------------- keys and tokens


def test_topic_keys_are_the_observed_ones():
    assert topic_key(0, "/robot1/cmd_vel", TWIST) == OBSERVED_KEY
    assert topic_key(0, "robot1/cmd_vel/", TWIST) == OBSERVED_KEY
    assert topic_key(0, "/robot1/cmd_vel", TWIST, "humble") == (
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported"
    )
    # a Jazzy TurtleBot3 in namespace robot1
    assert topic_key(0, "/robot1/cmd_vel", TWIST_STAMPED) == (
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/"
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
    )
    assert topic_key(7, "/robot1/odom", ODOMETRY) == (
        "7/robot1/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    )


def test_mangle_and_resolve():
    assert mangle("/robot1/cmd_vel") == "%robot1%cmd_vel"
    assert mangle("/") == mangle("") == "%"
    assert resolve("/tb3_0", "cmd_vel") == resolve("tb3_0/", "cmd_vel") == "/tb3_0/cmd_vel"
    assert resolve("", "cmd_vel") == resolve("/", "cmd_vel") == "/cmd_vel"
    assert resolve("/tb3_0", "/world/pose") == "/world/pose"


def test_qos_texts():
    assert QoS().encode() == "::,10:,:,:,,"
    assert QoS(depth=7).encode() == "::,7:,:,:,,"
    assert QoS(reliable=False, depth=5).encode() == "2::,5:,:,:,,"
    assert QoS(transient_local=True, depth=1).encode() == ":1:,1:,:,:,,"
    assert QoS(depth=42).encode() == "::,:,:,:,,"
    for q in (QoS(), QoS(depth=7), QoS(reliable=False, depth=5), QoS(transient_local=True, depth=1), QoS(depth=42)):
        assert QoS.decode(q.encode()) == q
    assert QoS.decode("1:2:1,10:,:,:,,") == QoS()
    for bad in ("", "::,10:,:,:", "::10:,:,:,,", "3::,10:,:,:,,", "::,x:,:,:,,"):
        with pytest.raises(ValueError):
            QoS.decode(bad)


def test_node_tokens_are_the_observed_ones():
    assert node_token(0, ZID, 0, "/", "sdk_listener") == OBSERVED_NN
    assert node_token(0, ZID, 0, "", "sdk_listener") == OBSERVED_NN
    assert node_token(0, ZID, 1, "/robot1", "sdk_teleop") == OBSERVED_NN_NS
    assert node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener", enclave="/") == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"  # rmw_zenoh design.md
    )


def test_entity_tokens_are_the_observed_ones():
    assert entity_token(0, ZID, 0, 0, "MS", "/", "sdk_listener", "/robot1/cmd_vel", TWIST, QoS()) == OBSERVED_MS
    assert entity_token(0, ZID, 1, 1, "MP", "/robot1", "sdk_teleop", "/robot1/cmd_vel", TWIST, QoS()) == OBSERVED_MP
    assert entity_token(0, ZID, 1, 1, "MP", "/robot1", "sdk_teleop", "cmd_vel", TWIST, QoS()) == OBSERVED_MP
    assert entity_token(0, ZID, 1, 1, "MP", "/robot1", "sdk_teleop", "cmd_vel", TWIST, QoS(), "humble") == (
        OBSERVED_MP.replace(TWIST_HASH, "TypeHashNotSupported")
    )
    with pytest.raises(ValueError):
        entity_token(0, ZID, 1, 1, "XX", "/robot1", "sdk_teleop", "cmd_vel", TWIST, QoS())


def test_parse_the_observed_tokens():
    assert parse_entity_token(OBSERVED_MS) == EntityInfo(
        kind="MS",
        namespace="/",
        node="sdk_listener",
        topic="/robot1/cmd_vel",
        dds_type="geometry_msgs::msg::dds_::Twist_",
        type_hash=TWIST_HASH,
        qos_text="::,10:,:,:,,",
        domain=0,
        zid=ZID,
        node_id=0,
        entity_id=0,
        enclave="/",
    )
    mp = parse_entity_token(OBSERVED_MP)
    assert mp is not None and (mp.kind, mp.namespace, mp.node, mp.node_id, mp.entity_id) == (
        "MP",
        "/robot1",
        "sdk_teleop",
        1,
        1,
    )
    assert mp.rtype is TWIST and mp.qos == QoS()
    nn = parse_entity_token(OBSERVED_NN_NS)
    assert nn is not None and (nn.kind, nn.namespace, nn.node, nn.topic, nn.rtype) == (
        "NN",
        "/robot1",
        "sdk_teleop",
        "",
        None,
    )
    rolling = parse_entity_token(OBSERVED_MP + "/some_backend")
    assert rolling is not None and rolling.topic == "/robot1/cmd_vel"


def test_parse_rejects_what_is_not_a_token():
    for bad in (
        OBSERVED_KEY,
        OBSERVED_NN.replace("@ros2_lv", "@ros2_lx"),
        OBSERVED_NN + "/extra",
        OBSERVED_NN.replace("/0/0/", "/0//"),
        OBSERVED_NN.replace("/0/0/", "/x/0/"),
        OBSERVED_NN.replace("/0/0/", "/\u00b2/0/"),
        OBSERVED_MS.replace("/MS/", "/MX/"),
        OBSERVED_MS.rsplit("/", 1)[0],
        OBSERVED_MS + "//",
        "",
    ):
        assert parse_entity_token(bad) is None, bad


names = st.from_regex(r"[a-z][a-z0-9_]{0,10}", fullmatch=True)
namespaces = st.lists(names, max_size=3).map(lambda parts: "/" + "/".join(parts))


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(
    st.integers(0, 232), st.integers(0, 10**6), st.integers(0, 10**6), st.sampled_from(["MP", "MS"]), namespaces,
    names, st.one_of(names, namespaces.filter(lambda n: n != "/")), st.sampled_from(TYPES),
    st.sampled_from(["jazzy", "humble"]),
    st.builds(QoS, st.booleans(), st.booleans(), st.integers(1, 1000)),
)  # fmt: skip
def test_entity_token_round_trip(domain, node_id, entity_id, kind, ns, node, topic, rtype, distro, qos):
    key = entity_token(domain, ZID, node_id, entity_id, kind, ns, node, topic, rtype, qos, distro)
    info = parse_entity_token(key)
    assert info is not None
    assert (info.kind, info.namespace, info.node, info.topic) == (kind, ns, node, resolve(ns, topic))
    assert (info.rtype, info.type_hash, info.qos) == (rtype, rtype.hash_for(distro), qos)
    assert (info.domain, info.zid, info.node_id, info.entity_id, info.enclave) == (domain, ZID, node_id, entity_id, "/")
    nn = parse_entity_token(node_token(domain, ZID, node_id, ns, node))
    assert nn is not None and (nn.kind, nn.namespace, nn.node, nn.node_id, nn.entity_id) == (
        "NN",
        ns,
        node,
        node_id,
        node_id,
    )


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(["@ros2_lv", "0", "12", "", "%", "MS", "NN", "x", "\u00b2", "%a%b"]), max_size=15))
def test_parse_never_raises(chunks):
    parse_entity_token("/".join(chunks))


# ---------------------------------------------------------------- attachment


def test_attachment_is_the_observed_layout():
    gid = bytes.fromhex("5fa26d14ccd447c29299b33564eee8c9")
    assert parse_attachment(OBSERVED_ATTACHMENT) == (0, 1795679404724756992, gid)
    assert attachment(0, 1795679404724756992, gid) == OBSERVED_ATTACHMENT
    a = attachment(1, 2, bytes(range(16)))
    assert len(a) == 33
    assert a == bytes.fromhex("0100000000000000020000000000000010") + bytes(range(16))
    assert attachment(-1, 0, gid)[:8] == b"\xff" * 8


def test_malformed_attachments_are_value_errors():
    gid = bytes(16)
    for bad in (
        b"",
        OBSERVED_ATTACHMENT[:32],
        OBSERVED_ATTACHMENT + b"\0",
        OBSERVED_ATTACHMENT[:16] + b"\x0f" + OBSERVED_ATTACHMENT[17:],
    ):
        with pytest.raises(ValueError):
            parse_attachment(bad)
    for gid_bad in (b"", bytes(15), bytes(17)):
        with pytest.raises(ValueError):
            attachment(1, 0, gid_bad)
    with pytest.raises(ValueError):
        attachment(2**63, 0, gid)


def test_gid_for_is_stable_and_16_bytes():
    assert gid_for(OBSERVED_MP) == gid_for(OBSERVED_MP) != gid_for(OBSERVED_MS)
    assert len(gid_for("")) == 16


def test_gid_is_rmw_zenohs_xxh3_of_the_liveliness_key():
    """rmw_zenoh's Entity: XXH3_128bits(key), low64 then high64, each little-endian. The
    published XXH3-128 of "hello" (high 0xB5E9C1AD071B3E7F, low 0xC779CFAA5E523818) fixes the
    byte order independently of the package the GID is computed with."""
    lo, hi = 0xC779CFAA5E523818, 0xB5E9C1AD071B3E7F
    assert gid_for("hello") == lo.to_bytes(8, "little") + hi.to_bytes(8, "little")
    for key in (OBSERVED_MP, OBSERVED_MS, "", "@ros2_lv/0/x"):
        assert len(gid_for(key)) == 16
