"""The robots' plant (swarm/robots/plant.py) before the world listens, and the ROS graph while
it runs: `RobotGraph`, which `RobotPlant` is made of. `prepare` reaches the robots' router,
learns each robot's command type (`cmd_type_from`), declares the publishers and
subscriptions, stops every robot and waits for every robot's first pose, checks who publishes
each robot's poses, and from then on names every other publisher on a robot's topics; what it
notices is said by the plant's threads (`flush_notices`).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

from swarm.robots.config import RobotsError, RobotsFile
from swarm.robots.robot import Node, Robot, cmd_type_from, label
from swarm.ros2.attachment import gid_for, parse_attachment
from swarm.ros2.keys import EntityInfo

DISCOVERY_POLL = 0.25  # s between looks at the robots' tokens
MAX_SAID = 100  # notices kept for summary.json (its latest 20)


class RobotGraph:
    """The robots as reached through their router and seen in the ROS graph (the part of
    `RobotPlant` that `prepare` runs, and the graph watcher); `RobotPlant.__init__` sets these."""

    file: RobotsFile
    source: str
    robots: dict[int, Robot]
    session: Any
    node: Node | None
    open_session: Callable[[str], Any]
    make_node: Callable[[Any], Node]
    clock: Callable[[], float]
    cmd_wait: float
    pose_wait: float
    say: Callable[[str], None]
    notices: deque[str]  # the graph watcher's (zenoh's thread), said by ours
    said: list[str]  # every notice said (the latest MAX_SAID)
    _robot_keys: set[str]  # the robots' own pose publishers' tokens
    _names: dict[bytes, str]  # GID -> node, for the publishers the graph showed

    # -- prepare: before the world listens ---------------------------------------------------------
    def prepare(self) -> None:
        """Reach the robots' router, learn each robot's command type, declare our publishers and
        subscriptions, stop every robot, wait for every robot's first pose; RobotsError (one line:
        the robot, the topic) when something is missing."""
        connect = self.file.ros2.connect
        try:
            self.session = self.open_session(connect)
        except RobotsError:
            raise
        except Exception as e:  # zenoh.ZError: nothing answers there (its text ends with a source path)
            why = str(e).split(" at /", 1)[0]
            closed = " (a router closed with usrpwd refuses a wrong or missing [ros2] user and password_file)"
            raise RobotsError(
                f"{self.source}: cannot reach the robots' zenoh router at {connect} ([ros2] connect): {why}"
                + (closed if self.file.ros2.user is not None else "")
            ) from None
        self.node = self.make_node(self.session)
        self._learn_cmd_types()
        node = self.node
        for r in self.robots.values():
            assert r.cmd_type is not None
            r.publisher = node.publisher(r.cmd_topic, r.cmd_type)
            node.subscriber(r.pose_topic, r.pose_type, self._receiver(r), with_attachment=True)
        for r in self.robots.values():
            r.send(0.0, 0.0)  # standing still until the first tick
        self._wait_for_poses()
        self._check_pose_publishers()
        self._watch_the_graph()
        for aid, r in self.robots.items():
            assert r.cmd_type is not None
            self.say(
                f"robot {aid}: {r.spec.namespace or '/'} {r.spec.pose} on {r.pose_topic} -> "
                f"{r.cmd_topic} {r.cmd_type.short}"
            )

    def _receiver(self, r: Robot) -> Callable[..., None]:
        """The subscription's callback for robot `r` (zenoh's thread): its pose, stamped now."""
        return lambda payload, att=None: r.on_pose(payload, self.clock(), att)

    def _check_pose_publishers(self) -> None:
        """The publisher of each robot's poses in the ROS graph: one at most (RobotsError naming
        them when there are more: whose poses would the robot be?), whose GID, the XXH3 of its
        token as rmw_zenoh makes it, the robot's first pose should carry."""
        assert self.node is not None
        pubs = self.node.remote_entities(kind="MP", timeout=1.0)
        for r in self.robots.values():
            mine = [e for e in pubs if e.topic == r.pose_topic]
            if len(mine) > 1:
                names = ", ".join(sorted(self._name(e) for e in mine))
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: {len(mine)} publishers on {r.pose_topic} ({names}): "
                    "one robot's poses come from one publisher (stop the others, or set its pose_topic)"
                )
            if not mine:
                r.gid_checked = "first pose (no publisher token on the topic)"
                self._notice(
                    f"{r.label()}: no publisher of {r.pose_topic} in the ROS graph: trusting the GID of its first pose"
                )
                continue
            e = mine[0]
            self._robot_keys.add(e.key)
            self._names[gid_for(e.key)] = self._name(e)
            if r.gid is not None and r.gid == gid_for(e.key):
                r.gid_checked = f"token of {self._name(e)}"
            else:
                r.gid_checked = f"first pose (not the XXH3 of {self._name(e)}'s token)"
                self._notice(
                    f"{r.label()}: the poses on {r.pose_topic} do not carry the GID of {self._name(e)}'s token "
                    "(XXH3-128, as rmw_zenoh on Jazzy makes it): trusting the GID of its first pose"
                )

    def _watch_the_graph(self) -> None:
        """From now on, name at once every other publisher on a robot's pose or command topic
        (the ROS graph's tokens), and every sample on a command topic that is not ours."""
        node = self.node
        watch, listen = getattr(node, "watch", None), getattr(node, "listen", None)
        if watch is not None:
            watch(self._on_token)
        if listen is not None:
            for r in self.robots.values():
                listen(r.cmd_topic, self._command_watcher(r))

    def _command_watcher(self, r: Robot) -> Callable[[str, bytes, bytes | None], None]:
        def seen(_key: str, _payload: bytes, att: bytes | None) -> None:
            try:
                seq, _, gid = parse_attachment(att) if att is not None else (None, 0, None)
            except ValueError:
                seq, gid = None, None
            r.on_command_seen(gid, getattr(r.publisher, "gid", None), seq, getattr(r.publisher, "seq", None))

        return seen

    @staticmethod
    def _name(e: EntityInfo) -> str:
        ns = e.namespace.rstrip("/")
        return f"{ns}/{e.node} (zid {e.zid})"

    def _on_token(self, key: str, e: EntityInfo, alive: bool) -> None:
        """The graph watcher (zenoh's thread): a publisher on a robot's topic that is not the robot's."""
        if not alive or e.kind != "MP" or key in self._robot_keys:
            return
        name = self._name(e)
        self._names[gid_for(key)] = name
        for r in self.robots.values():
            if e.topic == r.pose_topic:
                what = "its poses are refused"
            elif e.topic == r.cmd_topic:
                what = "the robot obeys it as well as us"
            else:
                continue
            with r._lock:
                if name not in r.other_publishers:
                    r.other_publishers.append(name)
            self._notice(f"{r.label()}: another publisher on {e.topic}: {name}, {e.dds_type}: {what}")

    def _notice(self, line: str) -> None:
        self.notices.append(line)

    def flush_notices(self) -> None:
        """Say what the robots' callbacks and the graph watcher noticed (main or watchdog thread)."""
        for queue in (self.notices, *(r.notices for r in self.robots.values())):
            while True:
                try:
                    line = queue.popleft()
                except IndexError:
                    break
                line = self._named(line)
                self.said.append(line)
                del self.said[:-MAX_SAID]
                self.say(line)

    def _named(self, line: str) -> str:
        """A notice's "GID 0123456789ab" with the name of its node when the graph told us."""
        for gid, name in list(self._names.items()):
            text = f"GID {gid.hex()[:12]}"
            if text in line:
                return line.replace(text, f"{text}, {name}")
        return line

    def _learn_cmd_types(self) -> None:
        """cmd_type = "auto": the type of the robot's own subscription on its command topic."""
        assert self.node is not None
        waiting = [r for r in self.robots.values() if r.cmd_type is None]
        t_end = self.clock() + self.cmd_wait
        while waiting:
            seen = self.node.remote_entities(kind="MS", timeout=min(1.0, max(self.cmd_wait, 0.05)))
            for r in waiting:
                r.cmd_type = cmd_type_from(r.spec, seen, self.file.ros2.distro, self.source)
            waiting = [r for r in waiting if r.cmd_type is None]
            if waiting and self.clock() >= t_end:
                r = waiting[0]
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: nobody subscribes to {r.cmd_topic} (waited {self.cmd_wait:g} s "
                    f"for its token to learn its command type): is the robot up, in namespace "
                    f"{r.spec.namespace or '/'}, on ROS_DOMAIN_ID {self.file.ros2.domain}, behind "
                    f"{self.file.ros2.connect}? (or set its cmd_type)"
                )
            if waiting:
                time.sleep(DISCOVERY_POLL)

    def _wait_for_poses(self) -> None:
        t_end = self.clock() + self.pose_wait
        while True:
            missing = [r for r in self.robots.values() if r.latest is None]
            if not missing:
                return
            if self.clock() >= t_end:
                r = missing[0]
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: no {r.pose_type.short} on {r.pose_topic} within "
                    f"{self.pose_wait:g} s" + (f" ({r.malformed} malformed)" if r.malformed else "")
                )
            time.sleep(0.02)
