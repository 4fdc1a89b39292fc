"""The tables of a scenario file, each a strict, frozen pydantic model checked on its own:
[run], [target], [gains], [law], [sensing], [[agents]] and [[faults]].

The field names here are the contract between users, tools and every process of a
run. Units: metres, seconds, radians, m/s and rad/s throughout. What holds across
tables (the follow graph, the wire's and the recording's limits) and reading a file are
swarm/contracts/scenario.py's.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from swarm.contracts.laws import MAX_LAW_PARAMS, LawError, check_law
from swarm.contracts.tuning import SelectionTuning
from swarm.contracts.wire import MAX_AGENT_ID, MAX_AGENTS

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
AgentId = Annotated[int, Field(ge=0, le=MAX_AGENT_ID)]
# What the engine can honour: finite numbers it can square, add and take the sine of without
# overflow or losing the metre (a CC path from x = 1e308 overflows; a heading of 1e17 rad has
# no fractional part left), and waits a run can end within.
MAX_COORD = 1e7  # m: positions of agents and target, radii, ranges (10,000 km)
MAX_SPEED = 1e5  # m/s
MAX_ANGLE = 1e6  # rad: headings
MAX_RATE = 1e6  # rad/s and 1/s: turn-rate limits, gains
MAX_WAIT = 3600.0  # s: the lockstep deadline
Coord = Annotated[float, Field(ge=-MAX_COORD, le=MAX_COORD, allow_inf_nan=False)]
Length = Annotated[float, Field(gt=0, le=MAX_COORD, allow_inf_nan=False)]
Speed = Annotated[float, Field(gt=0, le=MAX_SPEED, allow_inf_nan=False)]
Angle = Annotated[float, Field(ge=-MAX_ANGLE, le=MAX_ANGLE, allow_inf_nan=False)]
Rate = Annotated[float, Field(gt=0, le=MAX_RATE, allow_inf_nan=False)]

MAX_SEED = 2**63 - 1  # fits a signed 64-bit integer wherever the seed is stored
# Trajectory arrays cost about 40 bytes per agent and tick: 2e8 agent-ticks is about 8 GB.
MAX_AGENT_TICKS = 200_000_000
RECORDING_LIMIT = "2e8 agent-ticks (about 8 GB)"


class Strict(BaseModel):
    # strict: a TOML string "1.5" or a boolean is not a number; integers are fine for floats.
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class RunSpec(Strict):
    """[run]: how the world steps."""

    dt: PositiveFloat = Field(default=0.01, description="world step (s)")
    duration: PositiveFloat = Field(default=60.0, description="simulated time to run (s)")
    clock: Literal["lockstep", "realtime"] = Field(
        default="lockstep", description="lockstep: step when every agent answered; realtime: wall clock"
    )
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = Field(
        default=0, description="seed for every random choice of the run (0 .. 2**63 - 1)"
    )
    on_dropout: Literal["leave", "coast"] = Field(
        default="leave",
        description="what the world does with a dead agent: leave the world, or coast uncontrolled",
    )
    lockstep_deadline: Annotated[float, Field(gt=0, le=MAX_WAIT, allow_inf_nan=False)] = Field(
        default=0.5,
        description="lockstep: wall seconds to wait for a live agent's command before holding its last one",
    )
    max_added_agents: Annotated[int, Field(ge=0, le=MAX_AGENTS)] | None = Field(
        default=None,
        description="agents that may be added while the run goes (swarm spawn of a new id); "
        "default 4 x the scenario's agents",
    )

    @model_validator(mode="after")
    def _steps(self) -> RunSpec:
        steps = self.duration / self.dt
        if not math.isfinite(steps) or steps > MAX_AGENT_TICKS:
            # even one agent would be too many for the recording (the scenario checks agents x ticks)
            raise ValueError(
                f"duration: {self.duration:g} s at dt = {self.dt:g} s is {steps:.3g} steps, more "
                f"than the recording limit of {RECORDING_LIMIT}; use a shorter run.duration "
                f"or a larger run.dt"
            )
        if self.ticks == 0:
            raise ValueError(f"duration: {self.duration:g} s is shorter than one step (dt = {self.dt:g} s)")
        return self

    @property
    def ticks(self) -> int:
        """Number of world steps in the run."""
        return int(round(self.duration / self.dt))


class TargetSpec(Strict):
    """[target]: the stationary target (m)."""

    x: Coord = 0.0
    y: Coord = 0.0


def check_law_field(name: str, kind: str, info: ValidationInfo) -> str:
    """A law named in the scenario, imported and checked for its signature. The validation
    context may give "law_dirs" (the scenario file's directory: load_scenario) and
    "check_laws": False (a scenario read back from a recording: nothing imported)."""
    ctx = info.context or {}
    if not ctx.get("check_laws", True):
        return name
    try:
        check_law(name, kind, ctx.get("law_dirs", ()))
    except LawError as e:
        raise ValueError(str(e)) from None
    except Exception as e:  # importing the module ran its code, and that failed
        what = "leader law" if kind == "leader" else "follower law"
        raise ValueError(f"{what} {name!r}: cannot import it: {type(e).__name__}: {e}") from None
    return name


class GainsSpec(Strict):
    """[gains]: the follower law's gains (and, in older scenarios, the follower law)."""

    c1: Rate = Field(description="gain on the heading difference wrap(g_j - g_i) (1/s)")
    c2: Rate = Field(description="gain on sin(lambda_ij - g_i) (rad/s)")
    law: str = Field(
        default="bearing",
        description="follower law of the older signature (g_i, g_j, lambda_ij, c1, c2): a registered "
        "name, or 'module:function'; anything but 'bearing' replaces [law] follower "
        "(see swarm/contracts/laws.py)",
    )

    @field_validator("law")
    @classmethod
    def _law_resolves(cls, name: str, info: ValidationInfo) -> str:
        return check_law_field(name, "gains", info)


class LawSpec(Strict):
    """[law]: the guidance laws, each law(obs) -> u (docs/guides/writing-a-law.md), and their
    parameters."""

    follower: str = Field(default="bearing", description="follower law: 'bearing' (the paper's) or 'module:function'")
    leader: str = Field(default="cc", description="leader law: 'cc' (CC path, then orbit hold) or 'module:function'")
    params: dict[str, Finite] = Field(
        default_factory=dict,
        max_length=MAX_LAW_PARAMS,
        description="[law.params]: numbers handed to the laws as obs.params",
    )

    @field_validator("follower")
    @classmethod
    def _follower_resolves(cls, name: str, info: ValidationInfo) -> str:
        return check_law_field(name, "follower", info)

    @field_validator("leader")
    @classmethod
    def _leader_resolves(cls, name: str, info: ValidationInfo) -> str:
        return check_law_field(name, "leader", info)


class SensingSpec(Strict):
    """[sensing]: who senses whom, and how followers pick their out-neighbour."""

    range: Length | None = Field(default=None, description="sensing range (m); unlimited if absent")
    fov: Annotated[float, Field(gt=0, le=2 * math.pi)] | None = Field(
        default=None, description="full field of view (rad) centred on the heading; 2*pi or absent = all round"
    )
    selection: Literal["sticky", "nearest", "fixed", "rooted"] = Field(
        default="sticky",
        description="sticky (default): the nearest sensed agent once it has a path to a leader, "
        "kept until it is lost (finitely many switches, loop-free); nearest: the "
        "paper's rule, re-chosen every tick (can form follower-only cycles); fixed: "
        "the agent named by each follower's `follow`; rooted: the nearest sensed "
        "agent that advertises a path to a leader, re-chosen every tick",
    )
    hysteresis: Annotated[float, Field(ge=0, lt=1)] = Field(
        default=0.0,
        description="nearest, fixed, rooted: switch to a new nearest agent only if it is this "
        "fraction closer than the current one (sticky ignores it)",
    )
    tuning: SelectionTuning = Field(
        default=SelectionTuning(),
        description="[sensing.tuning], sticky: its spells (s) and margins (docs/design/selection.md#tuning)",
    )


class AgentSpec(Strict):
    """[[agents]]: one unicycle."""

    id: Annotated[AgentId, Field(description="agent id (fits the int32 wire fields)")]
    role: Literal["leader", "follower"]
    x: Coord
    y: Coord
    heading: Angle = Field(description="initial heading (rad)")
    speed: Speed = Field(description="constant forward speed (m/s)")
    orbit_radius: Length | None = Field(default=None, description="leaders: orbit radius (m)")
    direction: Literal["ccw", "cw"] = Field(default="ccw", description="leaders: orbit direction")
    follow: AgentId | None = Field(default=None, description="followers: fixed out-neighbour id")
    max_turn_rate: Rate | None = Field(default=None, description="turn-rate limit (rad/s)")

    @model_validator(mode="after")
    def _role_fields(self) -> AgentSpec:
        if self.role == "leader":
            if self.orbit_radius is None:
                raise ValueError("orbit_radius: a leader needs an orbit radius (m)")
            if self.follow is not None:
                raise ValueError("follow: a leader has no out-neighbour; remove `follow`")
            if self.max_turn_rate is not None and self.orbit_radius < self.speed / self.max_turn_rate:
                raise ValueError(
                    f"orbit_radius: {self.orbit_radius} m is not reachable: speed / max_turn_rate = "
                    f"{self.speed / self.max_turn_rate:.6g} m"
                )
        else:
            if self.orbit_radius is not None:
                raise ValueError("orbit_radius: only leaders have one; a follower's radius follows from its speed")
        return self

    @property
    def direction_sign(self) -> int:
        """+1 for counter-clockwise, -1 for clockwise."""
        return 1 if self.direction == "ccw" else -1


FAULT_KINDS = ("kill", "restart", "freeze", "thaw", "partition", "loss", "delay", "noise")
PROCESS_FAULTS = ("kill", "restart", "freeze", "thaw")


class FaultSpec(Strict):
    """[[faults]]: one scripted fault, at a simulated time."""

    at: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(description="simulated time (s)")
    kind: Literal["kill", "restart", "freeze", "thaw", "partition", "loss", "delay", "noise"]
    agent: AgentId | None = Field(default=None, description="agent id; loss/delay/noise without it hit every agent")
    duration: PositiveFloat | None = Field(default=None, description="partition/loss/delay/noise: how long (s)")
    probability: Annotated[float, Field(ge=0, le=1)] | None = Field(default=None, description="loss: per message")
    what: Literal["sense", "cmd", "both"] = Field(default="both", description="loss: which messages")
    delay: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = Field(
        default=None, description="delay: added latency of sensor frames (s of simulated time)"
    )
    std: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = Field(
        default=None, description="noise: standard deviation on sensed bearings and headings (rad)"
    )

    @model_validator(mode="after")
    def _fields(self) -> FaultSpec:
        if self.kind in PROCESS_FAULTS + ("partition",) and self.agent is None:
            raise ValueError(f"agent: a {self.kind} fault needs an agent id")
        if self.kind in ("partition", "loss", "delay", "noise") and self.duration is None:
            raise ValueError(f"duration: a {self.kind} fault needs a duration (s)")
        needs = {"loss": "probability", "delay": "delay", "noise": "std"}.get(self.kind)
        if needs and getattr(self, needs) is None:
            raise ValueError(f"{needs}: a {self.kind} fault needs it")
        return self


def polygon_turns(points: Any) -> list[float]:
    """The cross product of each pair of consecutive edges of a polygon (corners (x, y)):
    all > 0, a convex polygon walked counter-clockwise; all < 0, clockwise."""
    n = len(points)
    out = []
    for k in range(n):
        (x0, y0), (x1, y1), (x2, y2) = points[k - 1], points[k], points[(k + 1) % n]
        out.append((x1 - x0) * (y2 - y1) - (y1 - y0) * (x2 - x1))
    return out


def is_convex_polygon(points: Any) -> bool:
    """Whether corners (x, y) walked in order make a convex polygon: every turn the same way
    (no repeated or collinear corners) and the turns adding up to one full turn, not two or
    more (a star such as a pentagram turns the same way at every corner but crosses itself)."""
    turns = polygon_turns(points)
    if not (all(t > 0 for t in turns) or all(t < 0 for t in turns)):
        return False
    n = len(points)
    total = 0.0
    for k in range(n):
        (x0, y0), (x1, y1), (x2, y2) = points[k - 1], points[k], points[(k + 1) % n]
        ax, ay, bx, by = x1 - x0, y1 - y0, x2 - x1, y2 - y1
        total += math.atan2(ax * by - ay * bx, ax * bx + ay * by)
    return abs(abs(total) - 2 * math.pi) < 1e-6


class SafetySpec(Strict):
    """[safety]: the safety filter between every law and every actuator (docs/design/safety.md):
    control barrier functions on the distance between agents and on the arena's walls, one
    small QP per tick in the world. Its figures (collisions, boundary exits, saturations)
    are measured whenever the table is there, filtering or not (`enabled = false`)."""

    enabled: bool = Field(default=True, description="filter the commands; false: only measure")
    radius: Length = Field(description="the least distance between two agents' positions (m); closer is a collision")
    lookahead: Length | None = Field(
        default=None, description="the point ahead of each agent the barriers are on (m); default radius / 4"
    )
    gamma: Rate = Field(default=2.0, description="dh/dt >= -gamma h (1/s): how fast a barrier may be approached")
    speed: bool = Field(
        default=False, description="may the filter change speeds (slow down, stop): false for the paper's agents"
    )
    arena: list[Coord] | list[list[Coord]] | None = Field(
        default=None,
        description="[xmin, ymin, xmax, ymax], or a convex polygon's corners [[x, y], ...] (m); none: no walls",
    )

    @field_validator("arena")
    @classmethod
    def _arena(cls, arena: Any) -> Any:
        if arena is None or not arena or not isinstance(arena[0], list):
            if arena is not None and len(arena) != 4:
                raise ValueError(f"a rectangle is [xmin, ymin, xmax, ymax], got {len(arena)} numbers")
            if arena is not None and not (arena[0] < arena[2] and arena[1] < arena[3]):
                raise ValueError(f"a rectangle needs xmin < xmax and ymin < ymax, got {arena}")
            return arena
        for k, p in enumerate(arena):
            if len(p) != 2:
                raise ValueError(f"corner {k}: a corner is [x, y], got {len(p)} numbers")
        if len(arena) < 3:
            raise ValueError(f"a polygon needs 3 corners or more, got {len(arena)}")
        if not is_convex_polygon(arena):
            raise ValueError(
                "the polygon is not convex (or has repeated or collinear corners, or crosses itself):"
                " the walls are its edges"
            )
        return arena

    @property
    def lookahead_m(self) -> float:
        return self.lookahead if self.lookahead is not None else 0.25 * self.radius

    @property
    def corners(self) -> list[tuple[float, float]] | None:
        """The arena as corners (a rectangle's counter-clockwise from (xmin, ymin)); None: no arena."""
        a = self.arena
        if a is None:
            return None
        if isinstance(a[0], list):
            return [(float(p[0]), float(p[1])) for p in a]
        x0, y0, x1, y1 = (float(v) for v in a)
        return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]

    def inside(self, x: float, y: float) -> bool:
        """Whether the point (x, y) is in the arena (on a wall counts as in)."""
        pts = self.corners
        if pts is None:
            return True
        ccw = polygon_turns(pts)[0] > 0
        n = len(pts)
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
            if (cross < 0) if ccw else (cross > 0):
                return False
        return True

    def clearance(self, x: float, y: float) -> float:
        """The distance from (x, y) to the nearest wall's line (m): negative outside the arena,
        infinite with no arena."""
        pts = self.corners
        if pts is None:
            return math.inf
        sign = 1.0 if polygon_turns(pts)[0] > 0 else -1.0
        n = len(pts)
        out = math.inf
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
            out = min(out, sign * cross / math.hypot(x1 - x0, y1 - y0))
        return out
