"""Ros2Node on real zenoh sessions in this process (a router on a Unix socket in the test's tmp
dir, client sessions as a bridge to rmw_zenohd would be): samples with rmw_zenoh's attachment,
liveliness tokens byte for byte as rmw_zenoh writes them, the graph seen from another node,
close() taking the tokens away, and a subscription that hears its own type only."""

from __future__ import annotations

import math
import queue
import time

import pytest
import zenoh
import zenoh_ros2_sdk
import zenoh_ros2_sdk.message_registry
from deadlines import DEADLINE
from ros2_sdk_offline import sdk_offline

from swarm.ros2 import cdr
from swarm.ros2.attachment import parse_attachment
from swarm.ros2.keys import QoS, parse_entity_token
from swarm.ros2.node import Ros2Node
from swarm.ros2.types import ODOMETRY, TWIST, TWIST_STAMPED
from swarm.runtime.procs import wait_until

pytestmark = pytest.mark.slow  # zenoh sessions: a router and clients per test

TS_HASH = "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
NS = 1_000_000_000
ODOM_HASH = "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"


def _config(mode: str, ep: str) -> zenoh.Config:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", f'"{mode}"')
    cfg.insert_json5("listen/endpoints" if mode == "router" else "connect/endpoints", f'["{ep}"]')
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return cfg


@pytest.fixture
def net(tmp_path):
    """open() -> a new client session of a router listening on a Unix socket."""
    ep = f"unixsock-stream/{tmp_path / 'r.sock'}"
    router = zenoh.open(_config("router", ep))
    opened: list[zenoh.Session] = []

    def open_client() -> zenoh.Session:
        s = zenoh.open(_config("client", ep))
        opened.append(s)
        return s

    try:
        yield open_client
    finally:
        for s in reversed(opened):
            s.close()
        router.close()


def _tokens(session: zenoh.Session, domain: int = 0):
    """A queue of (kind, key) of the liveliness tokens of `domain`, from now on and those alive."""
    q: queue.Queue = queue.Queue()
    sub = session.liveliness().declare_subscriber(
        f"@ros2_lv/{domain}/**", lambda s: q.put((str(s.kind).rsplit(".", 1)[-1], str(s.key_expr))), history=True
    )
    return q, sub


def _drain_until(q: queue.Queue, want: set, timeout: float = DEADLINE) -> set:
    """Take items from `q` until every one of `want` came (or `timeout`); what came."""
    seen: set = set()
    deadline = time.monotonic() + timeout
    while not want <= seen and time.monotonic() < deadline:
        try:
            seen.add(q.get(timeout=0.05))
        except queue.Empty:
            pass
    return seen


def test_samples_reach_the_subscriber_with_attachments_from_seq_1(net):
    a, b = net(), net()
    world = Ros2Node(a, "swarm_world")
    robot = Ros2Node(b, "turtlebot3_node", "/robot1")
    got: queue.Queue = queue.Queue()
    robot.subscriber("cmd_vel", TWIST_STAMPED, got.put)
    raw: queue.Queue = queue.Queue()  # what is on the wire: payload and attachment
    b.declare_subscriber(
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/" + TS_HASH,
        lambda s: raw.put((s.payload.to_bytes(), None if s.attachment is None else s.attachment.to_bytes())),
    )
    pub = world.publisher("/robot1/cmd_vel", TWIST_STAMPED)
    assert pub.key == "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/" + TS_HASH
    assert wait_until(lambda: pub.has_subscribers, DEADLINE), "the subscription never reached the publisher"
    before = time.time_ns()
    payloads = [cdr.encode_twist_stamped(i, "base_link", 0.1 * i, -0.2 * i) for i in range(1, 6)]
    for p in payloads:
        pub.put(p)
    after = time.time_ns()
    assert [got.get(timeout=5) for _ in payloads] == payloads
    wire = [raw.get(timeout=5) for _ in payloads]
    assert [p for p, _ in wire] == payloads
    atts = [parse_attachment(att) for _, att in wire]  # 33 bytes each, or ValueError
    assert [seq for seq, _, _ in atts] == [1, 2, 3, 4, 5]
    assert all(gid == pub.gid for _, _, gid in atts) and len(pub.gid) == 16
    stamps = [stamp for _, stamp, _ in atts]
    assert before <= stamps[0] and stamps == sorted(stamps) and stamps[-1] <= after
    assert pub.seq == 5
    assert got.empty() and raw.empty()


def test_tokens_are_written_as_rmw_zenoh_writes_them(net):
    a, watcher = net(), net()
    seen, _sub = _tokens(watcher, domain=3)
    world = Ros2Node(a, "swarm_world", domain=3)
    robot = Ros2Node(a, "turtlebot3_node", namespace="robot1", domain=3)
    cmd = world.publisher("/robot1/cmd_vel", TWIST_STAMPED)
    odom = world.subscriber("/robot1/odom", ODOMETRY, lambda _: None, QoS(reliable=False, depth=5))
    robot_cmd = robot.subscriber("cmd_vel", TWIST_STAMPED, lambda _: None)
    zid = str(a.info.zid())
    w, r = world.node_id, robot.node_id
    want = {
        f"@ros2_lv/3/{zid}/{w}/{w}/NN/%/%/swarm_world",
        f"@ros2_lv/3/{zid}/{r}/{r}/NN/%/%robot1/turtlebot3_node",
        f"@ros2_lv/3/{zid}/{w}/{cmd.entity_id}/MP/%/%/swarm_world/%robot1%cmd_vel/"
        f"geometry_msgs::msg::dds_::TwistStamped_/{TS_HASH}/::,10:,:,:,,",
        f"@ros2_lv/3/{zid}/{w}/{odom.entity_id}/MS/%/%/swarm_world/%robot1%odom/"
        f"nav_msgs::msg::dds_::Odometry_/{ODOM_HASH}/2::,5:,:,:,,",
        f"@ros2_lv/3/{zid}/{r}/{robot_cmd.entity_id}/MS/%/%robot1/turtlebot3_node/%robot1%cmd_vel/"
        f"geometry_msgs::msg::dds_::TwistStamped_/{TS_HASH}/::,10:,:,:,,",
    }
    assert len({w, r, cmd.entity_id, odom.entity_id, robot_cmd.entity_id}) == 5  # ids unique in the session
    assert {world.token_key, robot.token_key, cmd.token_key, odom.token_key, robot_cmd.token_key} == want
    came = _drain_until(seen, {("PUT", k) for k in want})
    assert {k for kind, k in came if kind == "PUT"} == want  # on the wire, and nothing else
    for key in want:
        info = parse_entity_token(key)
        assert info is not None and info.zid == zid and info.domain == 3
    info = parse_entity_token(robot_cmd.token_key)
    assert info is not None
    assert (info.kind, info.namespace, info.node, info.topic, info.rtype, info.qos) == (
        "MS",
        "/robot1",
        "turtlebot3_node",
        "/robot1/cmd_vel",
        TWIST_STAMPED,
        QoS(),
    )


def test_remote_entities_finds_another_nodes_subscription(net):
    a, b = net(), net()
    world = Ros2Node(a, "swarm_world")
    world.publisher("/tb3_0/cmd_vel", TWIST_STAMPED)  # its own: not a remote entity
    robot = Ros2Node(b, "turtlebot3_node", "/tb3_0")
    robot.subscriber("cmd_vel", TWIST_STAMPED, lambda _: None)
    robot.publisher("odom", ODOMETRY)
    humble = Ros2Node(b, "old_robot", "/tb3_1", distro="humble")
    humble.subscriber("cmd_vel", TWIST, lambda _: None)

    found = wait_until(lambda: world.remote_entities("/tb3_0/cmd_vel", "MS", timeout=0.5), 5)
    assert found, "the robot's subscription never showed"
    [ms] = found
    assert (ms.kind, ms.namespace, ms.node, ms.topic) == ("MS", "/tb3_0", "turtlebot3_node", "/tb3_0/cmd_vel")
    assert (ms.dds_type, ms.type_hash, ms.rtype, ms.qos_text) == (
        "geometry_msgs::msg::dds_::TwistStamped_",
        TS_HASH,
        TWIST_STAMPED,
        "::,10:,:,:,,",
    )
    assert ms.zid == str(b.info.zid())

    [old] = wait_until(lambda: world.remote_entities("/tb3_1/cmd_vel", "MS", timeout=0.5), 5)
    assert (old.rtype, old.type_hash) == (TWIST, "TypeHashNotSupported")

    def all_five():
        entities = world.remote_entities(timeout=0.5)
        return entities if len(entities) >= 5 else None

    everything = wait_until(all_five, DEADLINE)
    assert everything is not None
    assert sorted((e.kind, e.namespace, e.node, e.topic) for e in everything) == [
        ("MP", "/tb3_0", "turtlebot3_node", "/tb3_0/odom"),
        ("MS", "/tb3_0", "turtlebot3_node", "/tb3_0/cmd_vel"),
        ("MS", "/tb3_1", "old_robot", "/tb3_1/cmd_vel"),
        ("NN", "/tb3_0", "turtlebot3_node", ""),
        ("NN", "/tb3_1", "old_robot", ""),
    ]
    # and the robot sees the world's publisher; relative topics resolve in the asking node's namespace
    [mp] = wait_until(lambda: robot.remote_entities("cmd_vel", "MP", timeout=0.5), 5)
    assert (mp.node, mp.namespace, mp.rtype) == ("swarm_world", "/", TWIST_STAMPED)
    assert Ros2Node(b, "elsewhere", domain=1).remote_entities(timeout=0.3) == []


def test_close_removes_every_token(net):
    a, watcher = net(), net()
    seen, _sub = _tokens(watcher)
    node = Ros2Node(a, "swarm_world")
    pub = node.publisher("/tb3_0/cmd_vel", TWIST)
    node.subscriber("/tb3_0/odom", ODOMETRY, lambda _: None)
    keys = node.own_tokens()
    assert len(keys) == 3
    assert _drain_until(seen, {("PUT", k) for k in keys}) >= {("PUT", k) for k in keys}

    other = Ros2Node(watcher, "observer")
    assert wait_until(lambda: len(other.remote_entities(timeout=0.5)) == 3, 5)
    node.close()
    gone = {("DELETE", k) for k in keys}
    assert _drain_until(seen, gone) >= gone
    assert other.remote_entities(timeout=0.5) == []
    node.close()  # a second close does nothing
    with pytest.raises(RuntimeError):
        pub.put(cdr.encode_twist(0.0, 0.0))
    with pytest.raises(RuntimeError):
        node.publisher("/tb3_0/cmd_vel", TWIST)


def test_undeclare_takes_away_one_entity(net):
    a, watcher = net(), net()
    seen, _sub = _tokens(watcher)
    node = Ros2Node(a, "swarm_world")
    pub = node.publisher("/tb3_0/cmd_vel", TWIST)
    sub = node.subscriber("/tb3_0/odom", ODOMETRY, lambda _: None)
    assert _drain_until(seen, {("PUT", pub.token_key)})
    pub.undeclare()
    pub.undeclare()
    assert ("DELETE", pub.token_key) in _drain_until(seen, {("DELETE", pub.token_key)})
    assert node.own_tokens() == {node.token_key, sub.token_key}


def test_samples_of_another_type_or_distro_are_not_delivered(net):
    a, b = net(), net()
    robot = Ros2Node(b, "turtlebot3_node", "/tb3_0")
    got: queue.Queue = queue.Queue()
    robot.subscriber("cmd_vel", TWIST, got.put)
    world = Ros2Node(a, "swarm_world")
    stamped = world.publisher("/tb3_0/cmd_vel", TWIST_STAMPED)
    other_topic = world.publisher("/tb3_1/cmd_vel", TWIST)
    humble = Ros2Node(a, "humble_world", distro="humble").publisher("/tb3_0/cmd_vel", TWIST)
    right = world.publisher("/tb3_0/cmd_vel", TWIST)
    assert wait_until(lambda: right.has_subscribers, DEADLINE)
    assert not (stamped.has_subscribers or other_topic.has_subscribers or humble.has_subscribers)
    stamped.put(cdr.encode_twist_stamped(0, "", 9.0, 9.0))
    other_topic.put(cdr.encode_twist(8.0, 8.0))
    humble.put(cdr.encode_twist(7.0, 7.0))
    right.put(cdr.encode_twist(0.22, 0.5))
    assert cdr.decode_twist(got.get(timeout=5)) == (0.22, 0.5)
    right.put(cdr.encode_twist(0.1, 0.0))  # the same link, after the others: all of them had their chance
    assert cdr.decode_twist(got.get(timeout=5)) == (0.1, 0.0)
    assert got.empty()


def test_a_failing_callback_does_not_stop_the_subscription(net):
    a, b = net(), net()
    got: queue.Queue = queue.Queue()

    def on_sample(payload: bytes) -> None:
        vx, _ = cdr.decode_twist(payload)
        if vx < 0:
            raise ValueError("a bad sample")
        got.put(vx)

    Ros2Node(b, "robot").subscriber("/cmd_vel", TWIST, on_sample)
    pub = Ros2Node(a, "world").publisher("/cmd_vel", TWIST)
    assert wait_until(lambda: pub.has_subscribers, DEADLINE)
    pub.put(cdr.encode_twist(-1.0, 0.0))
    pub.put(cdr.encode_twist(1.0, 0.0))
    assert got.get(timeout=5) == 1.0


def test_bad_names_are_refused(net):
    a = net()
    with pytest.raises(ValueError):
        Ros2Node(a, "bad/name")
    with pytest.raises(ValueError):
        Ros2Node(a, "ok", namespace="/a b")
    node = Ros2Node(a, "ok")
    for topic in ("/tb3_0/*", "/a/**", "", "/a//b", "/a$"):
        with pytest.raises(ValueError):
            node.publisher(topic, TWIST)
    assert node.own_tokens() == {node.token_key}


def test_a_node_on_the_router_session_itself(tmp_path):
    """A simulated fleet may be the router (standing in for rmw_zenohd): its nodes' tokens and
    samples reach the clients."""
    ep = f"unixsock-stream/{tmp_path / 'r.sock'}"
    router = zenoh.open(_config("router", ep))
    client = zenoh.open(_config("client", ep))
    try:
        fleet = Ros2Node(router, "turtlebot3_node", "/tb3_0")
        odom = fleet.publisher("odom", ODOMETRY)
        cmds: queue.Queue = queue.Queue()
        fleet.subscriber("cmd_vel", TWIST, cmds.put)
        world = Ros2Node(client, "swarm_world")
        poses: queue.Queue = queue.Queue()
        world.subscriber("/tb3_0/odom", ODOMETRY, poses.put)
        cmd = world.publisher("/tb3_0/cmd_vel", TWIST)
        [ms] = wait_until(lambda: world.remote_entities("/tb3_0/cmd_vel", "MS", timeout=0.5), 5)
        assert (ms.node, ms.rtype, ms.zid) == ("turtlebot3_node", TWIST, str(router.info.zid()))
        assert wait_until(lambda: cmd.has_subscribers and odom.has_subscribers, DEADLINE)
        cmd.put(cdr.encode_twist(0.22, -1.0))
        odom.put(cdr.encode_odometry(1, "odom", "base_footprint", 0.5, 0.25, 0.0))
        assert cdr.decode_twist(cmds.get(timeout=5)) == (0.22, -1.0)
        assert cdr.decode_odometry(poses.get(timeout=5)) == cdr.Pose2D(1, 0.5, 0.25, 0.0, "odom")
        fleet.close()
        assert wait_until(lambda: world.remote_entities(timeout=0.5) == [], 5)
    finally:
        client.close()
        router.close()


# ---------------------------------------------------------------- interop: ROBOTIS' zenoh-ros2-sdk as the robot


@pytest.fixture
def sdk(tmp_path, monkeypatch):
    """A router on a Unix socket; the SDK's (process-wide) session connects to it as a client,
    with message definitions from rosbags and its git cache in the tmp dir."""
    ep = f"unixsock-stream/{tmp_path / 'r.sock'}"
    router = zenoh.open(_config("router", ep))
    sdk_offline(monkeypatch, tmp_path, ep, [ODOMETRY.name, TWIST_STAMPED.name])
    ours = zenoh.open(_config("client", ep))
    try:
        yield ours
    finally:
        ours.close()
        if zenoh_ros2_sdk.ZenohSession._instance is not None:
            zenoh_ros2_sdk.ZenohSession._instance.close()
        router.close()
        assert not (tmp_path / "cache").exists(), "the SDK tried to fetch message definitions"


def test_interop_with_zenoh_ros2_sdk(sdk):
    """Our node as a TurtleBot3 (odom publisher, cmd_vel subscription); the SDK as the world:
    each hears the other, and each sees the other's tokens."""
    robot = Ros2Node(sdk, "turtlebot3_node", "/robot1")
    cmds: queue.Queue = queue.Queue()
    robot.subscriber("cmd_vel", TWIST_STAMPED, cmds.put)
    odom = robot.publisher("odom", ODOMETRY)
    raw: queue.Queue = queue.Queue()  # the SDK's attachments on the wire
    sdk.declare_subscriber(
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/" + TS_HASH,
        lambda s: raw.put(None if s.attachment is None else s.attachment.to_bytes()),
    )

    poses: queue.Queue = queue.Queue()
    sdk_pub = zenoh_ros2_sdk.ROS2Publisher(topic="/robot1/cmd_vel", msg_type=TWIST_STAMPED.name, node_name="sdk_world")
    sdk_sub = zenoh_ros2_sdk.ROS2Subscriber(
        topic="/robot1/odom", msg_type=ODOMETRY.name, callback=poses.put, node_name="sdk_world"
    )
    assert sdk_pub.keyexpr == "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/" + TS_HASH
    assert sdk_pub.type_hash == TWIST_STAMPED.rihs01  # the SDK's own RIHS01 of the .msg text

    # the SDK's twist reaches our subscription
    T = sdk_pub.session_mgr.store.types
    twist = T["geometry_msgs/msg/Twist"](
        linear=T["geometry_msgs/msg/Vector3"](x=0.22, y=0.0, z=0.0),
        angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.5),
    )
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="base_link")

    def twist_came():
        sdk_pub.publish(header=header, twist=twist)
        try:
            return cmds.get(timeout=0.2)
        except queue.Empty:
            return None

    payload = wait_until(twist_came, DEADLINE, interval=0)
    assert payload is not None, "no TwistStamped from the SDK"
    assert cdr.decode_twist_stamped(payload) == (1 * NS + 2, "base_link", 0.22, 0.5)
    seq, _, gid = parse_attachment(raw.get(timeout=5))  # the SDK's attachment parses as rmw_zenoh's
    assert seq >= 0 and len(gid) == 16

    # our odometry reaches the SDK's subscription (rosbags deserializes it there)
    def pose_came():
        odom.put(cdr.encode_odometry(5 * NS + 6, "odom", "base_footprint", 1.5, -0.5, 0.75, 0.22, 0.5))
        try:
            return poses.get(timeout=0.2)
        except queue.Empty:
            return None

    msg = wait_until(pose_came, DEADLINE, interval=0)
    assert msg is not None, "no Odometry at the SDK"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, msg.child_frame_id) == (
        5,
        6,
        "odom",
        "base_footprint",
    )
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    assert (p.x, p.y) == (1.5, -0.5) and math.isclose(2 * math.atan2(q.z, q.w), 0.75)
    assert (msg.twist.twist.linear.x, msg.twist.twist.angular.z) == (0.22, 0.5)

    # each side's graph shows the other
    [mp] = wait_until(lambda: robot.remote_entities("cmd_vel", "MP", timeout=0.5), 5)
    assert (mp.node, mp.namespace, mp.rtype, mp.type_hash, mp.qos) == ("sdk_world", "/", TWIST_STAMPED, TS_HASH, QoS())
    [ms] = wait_until(lambda: robot.remote_entities("odom", "MS", timeout=0.5), 5)
    assert (ms.node, ms.rtype) == ("sdk_world", ODOMETRY)
    topics = dict(zenoh_ros2_sdk.get_topic_names_and_types(timeout=0.5))
    assert topics["/robot1/cmd_vel"] == [TWIST_STAMPED.name] and topics["/robot1/odom"] == [ODOMETRY.name]
    info = zenoh_ros2_sdk.get_topic_info("/robot1/odom", timeout=0.5, verbose=True)
    assert info is not None and [(e.node_name, e.node_namespace) for e in info.publishers] == [
        ("turtlebot3_node", "/robot1")
    ]

    sdk_pub.close()
    sdk_sub.close()
    robot.close()
