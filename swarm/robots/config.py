"""The robots file (`swarm up SCENARIO --robots FILE`, `swarm robots sim SCENARIO --robots
FILE`): which ROS 2 robot each agent drives, where its pose comes from, where its command
goes, and its limits. Validated like a scenario: a bad file raises `RobotsError` naming the
file and the field (exit 2).

    [ros2]
    connect = "tcp/192.168.1.10:7447"  # the robots' zenoh router (rmw_zenohd); client mode
    domain = 0                         # ROS_DOMAIN_ID
    distro = "jazzy"                   # jazzy (RIHS01 type hashes) | humble (TypeHashNotSupported)
    stale_after = 0.5                  # s: a robot whose last pose is older gets a zero twist
    predict = false                    # true: each pose carried forward from its stamp to the tick
                                       # with the robot's last twist (latency compensation; needs the
                                       # robots' clocks synchronised with this machine's, e.g. chrony)
    user = "swarm"                     # a router closed with usrpwd: our user ...
    password_file = "robots.password"  # ... and a file holding its password (relative: to this file)
    root_ca = "ca.pem"                 # a tls/ connect: the CA that signed the router's certificate
    tls_cert = "swarm.pem"             # mutual TLS: our certificate and key (both or neither)
    tls_key = "swarm.key"
    pose_margin = 0.5                  # a pose implying motion above (1 + margin) x the robot's limits ...
    pose_slack = 0.1                   # ... plus this many m (and 5x as many rad) is refused

    [[robots]]
    agent = 1                # the scenario's agent id
    namespace = "/tb3_0"     # the robot's ROS namespace ("" for none)
    pose = "odom"            # odom: nav_msgs/Odometry, relative to the agent's start pose in the
                             # scenario; mocap: geometry_msgs/PoseStamped in the world frame
    pose_topic = "odom"      # relative to the namespace (default: "odom", or "pose" for mocap)
    cmd_topic = "cmd_vel"    # relative to the namespace
    cmd_type = "auto"        # auto (the type the robot's own subscription announces) | Twist | TwistStamped
    max_linear = 0.22        # m/s (TurtleBot3 Burger)
    max_angular = 2.84       # rad/s
    quantize = 0.01          # the step of the robot's firmware (TurtleBot3: 0.01 m/s and rad/s;
                             # 0: none): the world sends and plans with whole steps

    [safety]                 # optional: the safety filter for these robots, as a scenario's [safety]
    radius = 0.3             # (docs/guides/scenarios.md#safety); replaces the scenario's table
    arena = [-2, -2, 2, 2]
    speed = true             # robots may slow down and stop

    [guard]                            # optional: swarm robots guard, on the robots' machine
    cmd_timeout = 0.5                  # s: a robot whose last command is older gets a zero twist
    connect = "tcp/127.0.0.1:7447"     # the router from there (default: [ros2] connect)
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from swarm.contracts.endpoints import EndpointError, check_endpoint
from swarm.contracts.scenario import Scenario, format_validation_error
from swarm.contracts.scenario_tables import SafetySpec
from swarm.contracts.tls import TLS
from swarm.contracts.vocabulary import Coded, ExitCode

MAX_ROBOTS_BYTES = 1 << 20
TURTLEBOT3_BURGER = (0.22, 2.84)  # max linear m/s, max angular rad/s


class RobotsError(Coded):
    """A robots file that cannot be used; the message names the file and the field."""

    exit_code = ExitCode.USAGE


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # max_linear = inf: refused


class Ros2Spec(_Strict):
    connect: str = Field(default="tcp/127.0.0.1:7447", description="the robots' zenoh router (client mode)")
    domain: int = Field(default=0, ge=0, le=232, description="ROS_DOMAIN_ID")
    distro: Literal["jazzy", "humble"] = "jazzy"
    stale_after: float = Field(default=0.5, gt=0.0, le=60.0, description="s; an older pose stops the robot")
    predict: bool = Field(default=False, description="carry each pose forward from its stamp to the tick")
    user: str | None = Field(default=None, min_length=1, description="usrpwd user on a closed router")
    password_file: Path | None = Field(default=None, description="the user's password, the file's first line")
    root_ca: Path | None = Field(default=None, description="tls/: the CA of the router's certificate")
    tls_cert: Path | None = Field(default=None, description="mutual TLS: our certificate")
    tls_key: Path | None = Field(default=None, description="mutual TLS: our private key")
    pose_margin: float = Field(default=0.5, ge=0.0, le=10.0, description="over the limits before refusing a pose")
    pose_slack: float = Field(default=0.1, ge=0.0, le=10.0, description="m of noise a pose may jump besides")

    @model_validator(mode="after")
    def _endpoint(self) -> Ros2Spec:
        try:
            check_endpoint(self.connect)
        except EndpointError as e:
            raise ValueError(f"connect: {e}") from None
        if (self.user is None) != (self.password_file is None):
            raise ValueError("user and password_file: give both (a router closed with usrpwd) or neither")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("tls_cert and tls_key: give both (mutual TLS) or neither")
        if (self.root_ca or self.tls_cert) and not self.connect.startswith("tls/"):
            raise ValueError(f"root_ca, tls_cert: TLS needs a tls/HOST:PORT connect, not {self.connect}")
        return self

    def relative_to(self, base: Path) -> Ros2Spec:
        """The file paths made relative to `base` (the robots file's folder) when not absolute."""
        update = {
            name: base / p
            for name in ("password_file", "root_ca", "tls_cert", "tls_key")
            if (p := getattr(self, name)) is not None and not p.is_absolute()
        }
        return self.model_copy(update=update)

    def password(self) -> str | None:
        """The password of `user` (the first line of password_file); RobotsError when unreadable."""
        if self.password_file is None:
            return None
        try:
            lines = self.password_file.read_text(encoding="utf-8").splitlines()
        except OSError as e:
            raise RobotsError(
                f"{self.password_file}: cannot read the password ([ros2] password_file): {e.strerror}"
            ) from None
        if not lines or not lines[0]:
            raise RobotsError(f"{self.password_file}: no password on its first line ([ros2] password_file)")
        return lines[0]

    def zenoh_settings(self) -> tuple[tuple[str, str] | None, dict]:
        """(usrpwd identity, TLS settings) for a zenoh client of the robots' router."""
        identity = (self.user, self.password() or "") if self.user is not None else None
        tls: dict = {}
        if self.root_ca is not None:
            tls[f"{TLS}/root_ca_certificate"] = str(self.root_ca)
        if self.tls_cert is not None:
            tls |= {
                f"{TLS}/connect_certificate": str(self.tls_cert),
                f"{TLS}/connect_private_key": str(self.tls_key),
                f"{TLS}/enable_mtls": True,
            }
        return identity, tls


class RobotSpec(_Strict):
    agent: int = Field(ge=0)
    namespace: str = ""
    pose: Literal["odom", "mocap"] = "odom"
    pose_topic: str | None = None
    cmd_topic: str = "cmd_vel"
    cmd_type: Literal["auto", "Twist", "TwistStamped"] = "auto"
    max_linear: float = Field(default=TURTLEBOT3_BURGER[0], gt=0.0)
    max_angular: float = Field(default=TURTLEBOT3_BURGER[1], gt=0.0)
    quantize: float = Field(default=0.0, ge=0.0, le=1.0, description="the firmware's step (0: none)")

    @model_validator(mode="after")
    def _names(self) -> RobotSpec:
        for field, value in (("namespace", self.namespace), ("cmd_topic", self.cmd_topic)):
            if any(c.isspace() for c in value) or "//" in value:
                raise ValueError(f"{field}: not a ROS name: {value!r}")
        return self

    @property
    def pose_topic_name(self) -> str:
        return self.pose_topic or ("odom" if self.pose == "odom" else "pose")

    def topic(self, name: str) -> str:
        """`name` under this robot's namespace, fully qualified ("/tb3_0/cmd_vel")."""
        if name.startswith("/"):
            return name
        ns = self.namespace.strip("/")
        return f"/{ns}/{name}" if ns else f"/{name}"


class GuardSpec(_Strict):
    """`swarm robots guard` (swarm/robots/guard.py), next to the robots' router."""

    cmd_timeout: float = Field(default=0.5, gt=0.0, le=60.0, description="s without a command: zero twist")
    connect: str | None = Field(default=None, description="the router, from the guard's machine (default [ros2])")

    @model_validator(mode="after")
    def _endpoint(self) -> GuardSpec:
        if self.connect is not None:
            try:
                check_endpoint(self.connect)
            except EndpointError as e:
                raise ValueError(f"connect: {e}") from None
        return self


class RobotsFile(_Strict):
    ros2: Ros2Spec = Ros2Spec()
    guard: GuardSpec = GuardSpec()  # swarm robots guard: its cmd_timeout, and the router from its machine
    robots: list[RobotSpec] = Field(min_length=1)
    # the safety filter for these robots (docs/design/safety.md), as a scenario's [safety];
    # it replaces the scenario's own table in robots mode (swarm/robots/plant.py `robot_scenario`)
    safety: SafetySpec | None = None

    @model_validator(mode="after")
    def _unique(self) -> RobotsFile:
        seen: set[int] = set()
        topics: dict[str, int] = {}
        for r in self.robots:
            if r.agent in seen:
                raise ValueError(f"agent {r.agent} has two robots")
            seen.add(r.agent)
            for topic in (r.topic(r.cmd_topic), r.topic(r.pose_topic_name)):
                other = topics.setdefault(topic, r.agent)
                if other != r.agent:  # two agents would drive one robot, or read one pose
                    raise ValueError(f"agents {other} and {r.agent} share the topic {topic} (one robot each)")
        return self

    def robot(self, agent: int) -> RobotSpec | None:
        return next((r for r in self.robots if r.agent == agent), None)


def parse_robots(data: dict, source: str = "<robots>") -> RobotsFile:
    try:
        return RobotsFile.model_validate(data)
    except ValidationError as e:
        raise RobotsError(format_validation_error(source, e, "robots file")) from None


def load_robots(path: str | Path) -> RobotsFile:
    """Read and validate a robots file; RobotsError naming the file and the field."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            raw = f.read(MAX_ROBOTS_BYTES + 1)
    except FileNotFoundError:
        raise RobotsError(f"{p}: no such file") from None
    except (OSError, ValueError) as e:
        raise RobotsError(f"{p}: cannot read: {getattr(e, 'strerror', None) or e}") from None
    if len(raw) > MAX_ROBOTS_BYTES:
        raise RobotsError(f"{p}: larger than 1 MiB; not a robots file")
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError) as e:
        raise RobotsError(f"{p}: cannot parse: {e}") from None
    robots = parse_robots(data, str(p))
    return robots.model_copy(update={"ros2": robots.ros2.relative_to(p.parent)})


def check_against(robots: RobotsFile, scenario: Scenario, source: str) -> list[str]:
    """RobotsError when the file and the scenario disagree (a robot for an agent the scenario
    does not have, an agent without a robot); the warnings (one line each) when an agent asks
    for more than its robot can do (a constant speed above max_linear: the law's assumption of
    a constant speed breaks; a turn-rate limit above max_angular)."""
    ids = {a.id for a in scenario.agents}
    extra = sorted({r.agent for r in robots.robots} - ids)
    if extra:
        raise RobotsError(f"{source}: robots.agent {extra[0]}: the scenario has no agent {extra[0]}")
    missing = sorted(ids - {r.agent for r in robots.robots})
    if missing:
        raise RobotsError(f"{source}: no robot for agent {missing[0]} (every agent of the scenario needs one)")
    warnings = []
    for a in scenario.agents:
        r = robots.robot(a.id)
        assert r is not None
        if a.speed > r.max_linear:
            warnings.append(
                f"agent {a.id}: speed {a.speed:g} m/s is above its robot's max_linear {r.max_linear:g} m/s "
                "(the robot will be saturated and the law's constant speed will not hold)"
            )
        if r.quantize > 0.0 and abs(a.speed / r.quantize - round(a.speed / r.quantize)) > 1e-6:
            steps = min(round(a.speed / r.quantize), math.floor(r.max_linear / r.quantize + 1e-9))
            warnings.append(
                f"agent {a.id}: speed {a.speed:g} m/s is not a whole number of its robot's steps "
                f"(quantize {r.quantize:g}): its motors get {steps * r.quantize:g} m/s, which the world "
                "sends and plans with (expected radii)"
            )
        if a.max_turn_rate is None or a.max_turn_rate > r.max_angular:
            warnings.append(
                f"agent {a.id}: turn rates are saturated at its robot's max_angular {r.max_angular:g} rad/s "
                f"(the scenario's max_turn_rate is {a.max_turn_rate if a.max_turn_rate is not None else 'unset'})"
            )
    return warnings
