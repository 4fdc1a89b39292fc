"""The robots' plant (world/plant.py `Plant`): a world whose physics is ROS 2 robots reached
through rmw_zenoh, `swarm up SCENARIO --robots FILE` / `swarm world SCENARIO --robots FILE`
(docs/guides/robots.md).

The agent processes are unchanged: the world builds their frames from the robots' poses and
sends each agent's turn rate to its robot. Per robot of the robots file (swarm/robots/config.py):

- poses: nav_msgs/Odometry (`pose = "odom"`: the odom frame starts where the agent starts in
  the scenario, so world pose = start pose composed with the odometry pose) or
  geometry_msgs/PoseStamped (`pose = "mocap"`: already in the world frame);
- commands: Twist or TwistStamped (`cmd_type`; "auto": the type the robot's own subscription
  token announces) with linear.x = the agent's constant speed saturated at max_linear and
  angular.z = its turn rate saturated at max_angular.

Safety: a robot gets a zero twist when its agent is gone (not when it coasts: that is straight
on at its speed, as on_dropout = "coast" says), when its latest pose is older than
`[ros2] stale_after` (a `stale` event, `fresh` when poses come again), while the world's clock
holds (a pause, a scripted fault) and at the end, however the world ends (`stop`); and a
watchdog thread stops every robot when the world's main thread has sent no command for
stale_after (a stalled or starved world) until the next tick. A world killed with SIGKILL
(or stopped with SIGSTOP) sends nothing: the robot side must stop a robot whose commands
stop (docs/guides/robots.md). Pose ages (since each pose was received, in the run's seconds: wall
seconds times the time scale) are measured at every tick: their maximum and median per agent
are in summary.json's `robots` section, with the delays from the poses' stamps to their
reception (which include any offset between the robot's clock and ours).

Everything that talks to the robots goes through swarm.ros2's `Ros2Node`; the decisions
(`odom_to_world`, `twist_for`, `PoseAges`: swarm/robots/pose.py; `cmd_type_from`:
swarm/robots/robot.py) are pure functions and classes. One robot is a `Robot`
(swarm/robots/robot.py); reaching them before the run and watching the ROS graph is
`RobotGraph` (swarm/robots/discovery.py), what `RobotPlant` is made of; the run is here.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.robots.config import RobotsFile
from swarm.robots.discovery import RobotGraph
from swarm.robots.pose import planned_speed, predicted, twist_for
from swarm.robots.robot import Node, Robot, open_robots_session, ros2_node
from swarm.world.core import WorldCore
from swarm.world.plant import EventSink

CMD_WAIT = 5.0  # s to wait for a robot's subscription token (cmd_type = "auto")
POSE_WAIT = 10.0  # s to wait for every robot's first pose
STOP_REPEAT = 3  # zero twists sent to each robot at the end (reliable, but a robot must not miss it)
STOP_GAP = 0.02  # s between them
WATCHDOG_PERIOD = 0.05  # s between the watchdog's looks


ROBOTS_CLOCK = "realtime"


def robot_scenario(scenario: Scenario, robots: RobotsFile | None = None) -> Scenario:
    """`scenario` as the robot world runs it: the realtime clock, and no agent added while it
    runs (`swarm spawn`: every agent needs a robot of the robots file); with `robots`, each
    agent's speed the one its robot's motors get (`planned_speed`: a whole number of the
    robot's `quantize` steps, within its max_linear), which the world plans with (its
    expected radii) and sends, and its [safety] table, if it has one, in place of the
    scenario's (docs/design/safety.md)."""
    run = scenario.run.model_copy(update={"clock": ROBOTS_CLOCK, "max_added_agents": 0})
    update: dict[str, Any] = {"run": run}
    if robots is not None:
        agents = []
        for a in scenario.agents:
            spec = robots.robot(a.id)
            speed = a.speed if spec is None else planned_speed(a.speed, spec)
            agents.append(a if speed == a.speed else a.model_copy(update={"speed": speed}))
        update["agents"] = agents
        if robots.safety is not None:  # the robots file's [safety] table: the filter for these robots
            update["safety"] = robots.safety
    return scenario.model_copy(update=update)


class RobotPlant(RobotGraph):
    """The robots of `robots` as the world's plant for `scenario` (whose agents each have a robot:
    swarm/robots/config.py `check_against`). `source` names the robots file in errors.
    `open_session(connect)` and `make_node(session)` reach the robots (tests pass their own);
    `clock` is monotonic seconds; `time_scale` the run's (ages are in the run's seconds)."""

    def __init__(
        self,
        robots: RobotsFile,
        scenario: Scenario,
        source: str = "<robots>",
        *,
        time_scale: float = 1.0,
        open_session: Callable[[str], Any] | None = None,
        make_node: Callable[[Any], Node] | None = None,
        clock: Callable[[], float] = time.monotonic,
        cmd_wait: float = CMD_WAIT,
        pose_wait: float = POSE_WAIT,
        say: Callable[[str], None] | None = None,
        watchdog: bool = True,
    ):
        self.file = robots
        self.source = source
        self.stale_after = robots.ros2.stale_after
        self.predict = robots.ros2.predict
        self.time_scale = time_scale
        self.open_session = open_session or (lambda connect: open_robots_session(connect, robots.ros2))
        self.make_node = make_node or (lambda session: ros2_node(session, robots))
        self.clock = clock
        self.cmd_wait, self.pose_wait = cmd_wait, pose_wait
        self.say = say or (lambda line: None)
        self.robots: dict[int, Robot] = {}
        for a in scenario.agents:
            spec = robots.robot(a.id)
            if spec is not None:
                self.robots[a.id] = Robot(
                    spec,
                    (a.x, a.y, a.heading),
                    source,
                    time_scale=time_scale,
                    margin=robots.ros2.pose_margin,
                    slack=robots.ros2.pose_slack,
                    grace=2.0 * robots.ros2.stale_after,
                )
        self.session: Any = None
        self.node: Node | None = None
        self.event: EventSink | None = None
        self.stopped = False
        self.watchdog = watchdog
        self.watchdog_stops = 0  # times the watchdog stopped the robots (the world sent nothing for stale_after)
        self._send_lock = threading.Lock()  # the main thread's commands and the watchdog's zeros
        self._moving_since: float | None = None  # clock() of the last commands, None once all were zero
        self._quit = threading.Event()
        self._watch: threading.Thread | None = None
        self._robot_keys: set[str] = set()  # the robots' own pose publishers' tokens
        self._names: dict[bytes, str] = {}  # GID -> node, for the publishers the graph showed
        self.notices: deque[str] = deque()  # the graph watcher's (zenoh's thread), said by ours
        self.said: list[str] = []  # every notice said (the latest MAX_SAID)

    # -- the run ------------------------------------------------------------------------------------
    def start(self, core: WorldCore, event: EventSink) -> None:
        """Before tick 0: the poses of tick 0 are the robots' latest; the watchdog starts."""
        self.event = event
        for r in self.robots.values():
            r.freeze_origin()
        self._read_poses(core)
        if self.watchdog and self._watch is None:
            self._watch = threading.Thread(target=self._watchdog, name="robots-watchdog", daemon=True)
            self._watch.start()

    def step(self, core: WorldCore, u: np.ndarray) -> None:
        """This tick's commands out (zero for an agent gone or a stale robot), then the latest
        poses in."""
        now = self.clock()
        twists: dict[int, tuple[float, float]] = {}
        for aid, r in self.robots.items():
            k = core.index.get(aid)
            if k is None:
                continue
            latest = r.latest
            age = (now - latest[0]) * self.time_scale if latest is not None else math.inf
            change = r.ages.tick(age, self.stale_after)
            if change is not None and self.event is not None:
                self._announce(change, aid, r, age)
            stale = r.ages.stale
            twists[aid] = (
                (0.0, 0.0) if stale else twist_for(float(core.speed[k]), float(u[k]), *r.limits, r.spec.quantize)
            )
        with self._send_lock:
            for aid, (vx, wz) in twists.items():
                self.robots[aid].send(vx, wz)
            moving = any(t != (0.0, 0.0) for t in twists.values())
            self._moving_since = self.clock() if moving else None
        self._read_poses(core)
        self.flush_notices()

    def _watchdog(self) -> None:
        """Every robot stopped when the world has sent no command for stale_after (wall s: the
        run's over the time scale) while they were moving; the next step drives them again."""
        limit = self.stale_after / self.time_scale
        while not self._quit.wait(WATCHDOG_PERIOD):
            self.flush_notices()
            with self._send_lock:
                since = self._moving_since
                if since is None or self.clock() - since <= limit:
                    continue
                for r in self.robots.values():
                    self._quietly(r.send, 0.0, 0.0)
                self._moving_since = None
                self.watchdog_stops += 1
            self.say(f"robots: no command for {limit:g} s (the world stalled): every robot stopped until the next tick")

    def _announce(self, change: str, aid: int, r: Robot, age: float) -> None:
        assert self.event is not None
        if change == EventKind.STALE:
            self.event(
                EventKind.STALE,
                aid,
                f"no pose on {r.pose_topic} for {age:.2f} s (stale_after {self.stale_after:g} s): zero twist",
                age=age if math.isfinite(age) else None,
                topic=r.pose_topic,
            )
        else:
            self.event(
                EventKind.FRESH, aid, f"poses on {r.pose_topic} again ({age:.2f} s old)", age=age, topic=r.pose_topic
            )

    def _read_poses(self, core: WorldCore) -> None:
        x, y, g = core.x.copy(), core.y.copy(), core.heading.copy()
        now_ns = time.time_ns()
        for aid, r in self.robots.items():
            k = core.index.get(aid)
            latest = r.latest
            if k is not None and latest is not None:
                pose = latest[1]
                if self.predict and r.stamp_ns > 0:
                    age = (now_ns - r.stamp_ns) / 1e9 * self.time_scale
                    pose = predicted(pose, r.last_twist, age, self.stale_after)
                x[k], y[k], g[k] = pose
        core.x, core.y, core.heading = x, y, g

    def hold(self) -> None:
        """The clock holds: every robot stands still until the next step."""
        with self._send_lock:
            for r in self.robots.values():
                self._quietly(r.send, 0.0, 0.0)
            self._moving_since = None
        self.flush_notices()

    def stop(self) -> None:
        """Every robot stopped (zero twists, STOP_REPEAT times), then our node and session closed;
        whatever state prepare() got to. A second call does nothing."""
        if self.stopped:
            return
        self.stopped = True
        self._quit.set()
        if self._watch is not None:
            self._watch.join(1.0)
        for i in range(STOP_REPEAT):
            for r in self.robots.values():
                self._quietly(r.send, 0.0, 0.0)
            if i < STOP_REPEAT - 1 and any(r.publisher is not None for r in self.robots.values()):
                time.sleep(STOP_GAP)
        self._quietly(self.flush_notices)
        if self.node is not None:
            self._quietly(self.node.close)
        if self.session is not None:
            self._quietly(self.session.close)

    @staticmethod
    def _quietly(fn: Callable[..., Any], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:  # one robot's (or a closed session's) error must not keep the others going
            pass

    def figures(self) -> dict[str, Any]:
        """summary.json's `robots`: the router, stale_after, and per agent its robot's figures."""
        return {
            "connect": self.file.ros2.connect,
            "domain": self.file.ros2.domain,
            "distro": self.file.ros2.distro,
            "stale_after": self.stale_after,
            "watchdog_stops": self.watchdog_stops,
            # poses refused (another publisher's, or beyond a robot's limits), commands of another
            # publisher seen on a robot's topic, and other publishers named: 0, 0, [] in a clean run
            "refusals": sum(r.refused for r in self.robots.values()),
            "foreign_commands": sum(r.foreign_commands for r in self.robots.values()),
            "other_publishers": sorted({n for r in self.robots.values() for n in r.other_publishers}),
            "notices": list(self.said[-20:]),
            "agents": {str(aid): r.figures() for aid, r in self.robots.items()},
        }
