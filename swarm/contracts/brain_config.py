"""What one agent process needs to know about its run: its own spec, the gains, its laws
and their parameters, the selection rule, dt. Plain dataclasses (no pydantic: agent
processes stay small and start fast), built from the scenario by the world and sent in
the join reply as JSON, and checked again on arrival, since it comes off the network.

A BrainConf is the one configuration `AgentBrain` (and `StickyFollower`, the batch brains)
takes: whatever runs a brain (`swarm sim`, the batch engine, the environment, the agent
process) builds one first, from the scenario with `BrainConf.from_scenario`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from swarm.contracts.laws import MAX_LAW_PARAMS, follower_law_name
from swarm.contracts.tuning_ticks import TuningValues, tuning_values

if TYPE_CHECKING:
    from swarm.contracts.scenario import Scenario


@dataclass(frozen=True, slots=True)
class AgentConf:
    id: int
    role: str  # "leader" | "follower"
    speed: float  # m/s
    orbit_radius: float | None  # m (leaders)
    direction: str  # "ccw" | "cw" (leaders)
    follow: int | None  # pinned out-neighbour (followers)
    max_turn_rate: float | None  # rad/s

    @property
    def direction_sign(self) -> int:
        return 1 if self.direction == "ccw" else -1


@dataclass(frozen=True, slots=True)
class GainsConf:
    c1: float
    c2: float
    law: str


@dataclass(frozen=True, slots=True)
class LawConf:
    follower: str = "bearing"
    leader: str = "cc"
    params: dict[str, float] = field(default_factory=dict)  # name -> finite number


@dataclass(frozen=True, slots=True)
class SensingConf:
    selection: str  # "sticky" | "nearest" | "fixed" | "rooted"
    hysteresis: float
    range: float | None = None  # own sensor's range (m), None: unlimited (sets the search pattern)
    fov: float | None = None  # own sensor's field of view (rad), None: all round
    tuning: TuningValues = TuningValues()  # sticky: [sensing.tuning] (swarm/contracts/tuning.py)


@dataclass(frozen=True, slots=True)
class BrainConf:
    agent: AgentConf
    gains: GainsConf
    sensing: SensingConf
    dt: float  # s
    n_agents: int  # agents in the scenario: caps hop counts
    law: LawConf = LawConf()

    def law_names(self) -> list[str]:
        """The laws this agent imports: its leader law, or the follower law it runs."""
        if self.agent.role == "leader":
            return [self.law.leader]
        return [follower_law_name(self.gains.law, self.law.follower)[1]]

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["sensing"]["tuning"] = self.sensing.tuning._asdict()
        return d

    @classmethod
    def from_scenario(cls, scenario: Scenario, agent_id: int) -> BrainConf:
        """Agent `agent_id`'s configuration in `scenario`: the one way a Scenario becomes a
        brain's configuration (the world's join reply, `swarm sim`, the batch engine, the env)."""
        a = scenario.agent(agent_id)
        g, s = scenario.gains, scenario.sensing
        return cls(
            AgentConf(a.id, a.role, a.speed, a.orbit_radius, a.direction, a.follow, a.max_turn_rate),
            GainsConf(g.c1, g.c2, g.law),
            SensingConf(s.selection, s.hysteresis, s.range, s.fov, TuningValues(**s.tuning.model_dump())),
            scenario.run.dt,
            len(scenario.agents),
            LawConf(scenario.law.follower, scenario.law.leader, dict(scenario.law.params)),
        )

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> BrainConf:
        """Rebuild and check a BrainConf received over the network; ValueError names the field."""

        def num(obj: object, key: str, where: str, positive: bool = False, optional: bool = False) -> Any:
            v = obj.get(key) if isinstance(obj, dict) else None
            if v is None and optional:
                return None
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
                raise ValueError(f"{where}.{key}: expected a {'positive ' if positive else ''}finite number")
            return float(v)

        def integer(obj: object, key: str, where: str, optional: bool = False) -> Any:
            v = obj.get(key) if isinstance(obj, dict) else None
            if v is None and optional:
                return None
            if isinstance(v, bool) or not isinstance(v, int):
                raise ValueError(f"{where}.{key}: expected an integer")
            return v

        def choice(obj: object, key: str, where: str, options: tuple[str, ...]) -> Any:
            v = obj.get(key) if isinstance(obj, dict) else None
            if v not in options:
                raise ValueError(f"{where}.{key}: expected one of {options}")
            return v

        a, g, s = d.get("agent"), d.get("gains"), d.get("sensing")
        law = g.get("law") if isinstance(g, dict) else None
        if not isinstance(law, str):
            raise ValueError("gains.law: expected a string")
        agent = AgentConf(
            integer(a, "id", "agent"),
            choice(a, "role", "agent", ("leader", "follower")),
            num(a, "speed", "agent", positive=True),
            num(a, "orbit_radius", "agent", positive=True, optional=True),
            choice(a, "direction", "agent", ("ccw", "cw")),
            integer(a, "follow", "agent", optional=True),
            num(a, "max_turn_rate", "agent", positive=True, optional=True),
        )
        if agent.role == "leader" and agent.orbit_radius is None:
            raise ValueError("agent.orbit_radius: a leader needs one")
        return cls(
            agent,
            GainsConf(num(g, "c1", "gains"), num(g, "c2", "gains"), law),
            SensingConf(
                choice(s, "selection", "sensing", ("sticky", "nearest", "fixed", "rooted")),
                num(s, "hysteresis", "sensing"),
                num(s, "range", "sensing", positive=True, optional=True),
                num(s, "fov", "sensing", positive=True, optional=True),
                tuning_values(s.get("tuning") if isinstance(s, dict) else None),
            ),
            num(d, "dt", "brain", positive=True),
            integer(d, "n_agents", "brain"),
            _law_conf(d.get("law")),
        )


def _law_conf(d: object) -> LawConf:
    """The `law` object of a join reply (absent: the built-in laws); ValueError names the field."""
    if d is None:
        return LawConf()
    if not isinstance(d, dict):
        raise ValueError("law: expected an object")
    names, default = [], LawConf()
    for key in ("follower", "leader"):
        v = d.get(key, getattr(default, key))
        if not isinstance(v, str):
            raise ValueError(f"law.{key}: expected a string")
        names.append(v)
    params = d.get("params", {})
    if not isinstance(params, dict) or len(params) > MAX_LAW_PARAMS:
        raise ValueError(f"law.params: expected an object of at most {MAX_LAW_PARAMS} numbers")
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"law.params.{k}: expected a finite number")
    return LawConf(names[0], names[1], {k: float(v) for k, v in params.items()})
