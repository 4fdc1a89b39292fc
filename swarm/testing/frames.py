"""What a law is given, built from plain keyword arguments: `FrameBuilder` makes the
`Observation` a law gets (and the `SensorFrame` an agent gets), `Neighbour` places another
agent by its position or by its bearing and range. No zenoh, no running world, no scenario
file: bearings and ranges come from the world's own sensor model (the same bits as in a run).

    frames = FrameBuilder(role="follower", c1=1.0, c2=0.5)
    obs = frames.observation(heading=0.0, neighbours=[Neighbour(3, x=10.0, y=10.0)], out=3)
    assert my_law(obs) > 0  # the neighbour is ahead on the left: turn left

Positions and angles are in the world frame (m, rad, counter-clockwise from +x), as the world
computes them (swarm/world/sensing.py): a contact's bearing is the line-of-sight angle from
the agent to it, its range the distance; a leader's target is given where it is and handed
to the law relative to the agent. Bad input raises ValueError (TypeError for a wrong type)
naming the argument. See docs/guides/writing-a-law.md#unit-testing.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from swarm.contracts.brain_config import AgentConf, BrainConf, GainsConf, LawConf, SensingConf
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.laws import DEFAULT, FOLLOWER, GAINS, LEADER, MAX_LAW_PARAMS
from swarm.contracts.observation import Observation, Search
from swarm.contracts.orbits import wrap
from swarm.world.sensing import sensing_matrix

ROLES = ("follower", "leader")
DIRECTIONS = ("ccw", "cw")
SELECTIONS = ("sticky", "nearest", "fixed", "rooted")  # [sensing] selection (scenario default: sticky)


# -- checks: every message names the argument ------------------------------------------------------


def _number(where: str, name: str, value: object) -> float:
    """`value` as a finite float; TypeError / ValueError naming `where` and `name`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{where}: {name}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{where}: {name}: expected a finite number, got {value!r}")
    return float(value)


def _positive(where: str, name: str, value: object) -> float:
    v = _number(where, name, value)
    if v <= 0.0:
        raise ValueError(f"{where}: {name}: expected a positive number, got {value!r}")
    return v


def _optional_positive(where: str, name: str, value: object) -> float | None:
    return None if value is None else _positive(where, name, value)


def _integer(where: str, name: str, value: object, minimum: int | None = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{where}: {name}: expected an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{where}: {name}: expected an integer >= {minimum}, got {value!r}")
    return value


def _choice(where: str, name: str, value: object, options: tuple[str, ...]) -> str:
    if value not in options:
        raise ValueError(f"{where}: {name}: expected one of {options}, got {value!r}")
    return str(value)


def _point(where: str, name: str, value: object) -> tuple[float, float]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise TypeError(f"{where}: {name}: expected a pair of numbers (x, y), got {value!r}")
    return _number(where, f"{name}[0]", value[0]), _number(where, f"{name}[1]", value[1])


# -- another agent ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Neighbour:
    """Another agent the agent under test may sense: where it is, its heading, the hops to a
    leader it advertises (-1: none, 0: it is a leader) and, in a `FakeWorldLink`, how it
    moves (constant speed and turn rate; 0 and 0: it stays where it is).

    Place it by its position, `Neighbour(3, x=10.0, y=5.0)`, or as the agent sees it,
    `Neighbour(3, bearing=0.5, range=12.0)` (line-of-sight angle from the agent, world frame,
    and distance): one or the other."""

    id: int
    x: float | None = None
    y: float | None = None
    bearing: float | None = None
    range: float | None = None
    heading: float = 0.0
    hops: int = -1
    speed: float = 0.0
    turn_rate: float = 0.0

    def __post_init__(self) -> None:
        where = f"Neighbour({self.id!r})"
        _integer(where, "id", self.id)
        by_position = self.x is not None or self.y is not None
        by_sight = self.bearing is not None or self.range is not None
        if by_position and by_sight:
            raise ValueError(f"{where}: give x and y (its position) or bearing and range (as seen), not both")
        if by_sight:
            if self.bearing is None or self.range is None:
                raise ValueError(
                    f"{where}: {'range' if self.range is None else 'bearing'}: missing (bearing and range go together)"
                )
            _number(where, "bearing", self.bearing)
            if _number(where, "range", self.range) < 0.0:
                raise ValueError(f"{where}: range: expected a distance >= 0, got {self.range!r}")
        else:
            if self.x is None or self.y is None:
                raise ValueError(
                    f"{where}: {'y' if self.x is not None else 'x'}: missing (give x and y, or bearing and range)"
                )
            _number(where, "x", self.x)
            _number(where, "y", self.y)
        _number(where, "heading", self.heading)
        _integer(where, "hops", self.hops, minimum=-1)
        _number(where, "speed", self.speed)
        _number(where, "turn_rate", self.turn_rate)

    def position(self, x: float, y: float) -> tuple[float, float]:
        """Where it is (m), for an agent at (x, y)."""
        if self.bearing is not None and self.range is not None:
            return x + self.range * math.cos(self.bearing), y + self.range * math.sin(self.bearing)
        assert self.x is not None and self.y is not None  # (checked on construction)
        return self.x, self.y

    def placed(self, x: float, y: float) -> Neighbour:
        """The same neighbour given by its position (for an agent at (x, y))."""
        px, py = self.position(x, y)
        return Neighbour(self.id, px, py, None, None, self.heading, self.hops, self.speed, self.turn_rate)


# -- the agent under test, and what it is given ----------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class FrameBuilder:
    """The agent under test, as its scenario entry and [gains], [law.params] and [sensing]
    tables would describe it, and the frames and observations it gets.

    Defaults: a follower with id 1, speed 1 m/s, dt 0.01 s (the scenario's default), gains
    c1 = 1.0, c2 = 0.5, no turn-rate limit, the scenario's default selection ("sticky") and
    all-round sensing without a range. A leader needs `orbit_radius`."""

    id: int = 1
    role: str = "follower"
    speed: float = 1.0
    dt: float = 0.01
    c1: float = 1.0
    c2: float = 0.5
    params: Mapping[str, float] = field(default_factory=dict)
    max_turn_rate: float | None = None
    orbit_radius: float | None = None  # leaders (m)
    direction: str = "ccw"  # leaders: "ccw" (+1) or "cw" (-1)
    selection: str = "sticky"  # followers: [sensing] selection, how the agent picks `out`
    follow: int | None = None  # followers: the pinned out-neighbour (selection "fixed")
    hysteresis: float = 0.0
    sense_range: float | None = None  # m; None: unlimited
    fov: float | None = None  # full field of view (rad) centred on the heading; None: all round

    def __post_init__(self) -> None:
        w = "FrameBuilder"
        _integer(w, "id", self.id)
        _choice(w, "role", self.role, ROLES)
        _positive(w, "speed", self.speed)
        _positive(w, "dt", self.dt)
        _number(w, "c1", self.c1)
        _number(w, "c2", self.c2)
        if not isinstance(self.params, Mapping):
            raise TypeError(f"{w}: params: expected a mapping of names to numbers, got {self.params!r}")
        if len(self.params) > MAX_LAW_PARAMS:
            raise ValueError(f"{w}: params: at most {MAX_LAW_PARAMS} entries, got {len(self.params)}")
        for k, v in self.params.items():
            if not isinstance(k, str):
                raise TypeError(f"{w}: params: names are strings, got {k!r}")
            _number(w, f"params[{k!r}]", v)
        _optional_positive(w, "max_turn_rate", self.max_turn_rate)
        _optional_positive(w, "orbit_radius", self.orbit_radius)
        if self.role == "leader" and self.orbit_radius is None:
            raise ValueError(f"{w}: orbit_radius: a leader needs one (m)")
        _choice(w, "direction", self.direction, DIRECTIONS)
        _choice(w, "selection", self.selection, SELECTIONS)
        if self.follow is not None:
            _integer(w, "follow", self.follow)
        if self.selection == "fixed" and self.role == "follower" and self.follow is None:
            raise ValueError(f'{w}: follow: selection "fixed" needs the id of the agent to follow')
        h = _number(w, "hysteresis", self.hysteresis)
        if not 0.0 <= h < 1.0:
            raise ValueError(f"{w}: hysteresis: expected a fraction in [0, 1), got {self.hysteresis!r}")
        _optional_positive(w, "sense_range", self.sense_range)
        if _optional_positive(w, "fov", self.fov) is not None and self.fov is not None and self.fov > 2 * math.pi:
            raise ValueError(f"{w}: fov: expected at most 2 pi rad, got {self.fov!r}")

    @property
    def sign(self) -> int:
        """+1 counter-clockwise, -1 clockwise (`Observation.direction`)."""
        return 1 if self.direction == "ccw" else -1

    # -- what the agent's sensors give it ----------------------------------------------------------
    def contacts(
        self, *, x: float = 0.0, y: float = 0.0, heading: float = 0.0, neighbours: Iterable[Neighbour] = ()
    ) -> tuple[Contact, ...]:
        """The contacts of an agent at (x, y) with `heading`: every neighbour it senses (within
        `sense_range` and `fov`, like the world's sensors), in the order given."""
        return self._contacts("contacts", x, y, heading, neighbours)

    def _contacts(
        self, where: str, x: float, y: float, heading: float, neighbours: Iterable[Neighbour]
    ) -> tuple[Contact, ...]:
        x, y, heading = _number(where, "x", x), _number(where, "y", y), _number(where, "heading", heading)
        given = list(neighbours)
        seen: set[int] = set()
        for n in given:
            if not isinstance(n, Neighbour):
                raise TypeError(f"{where}: neighbours: expected Neighbour(...) entries, got {n!r}")
            if n.id == self.id:
                raise ValueError(f"{where}: neighbours: {n.id} is the agent's own id")
            if n.id in seen:
                raise ValueError(f"{where}: neighbours: id {n.id} given twice")
            seen.add(n.id)
        # neighbours placed by position: the world's own sensors (the same bits as in a run)
        placed = [n for n in given if n.bearing is None]
        by_id: dict[int, tuple[bool, float, float]] = {}
        if placed:
            px = np.array([x] + [n.x for n in placed], dtype=float)
            py = np.array([y] + [n.y for n in placed], dtype=float)
            ph = np.array([heading] + [n.heading for n in placed], dtype=float)
            sensed, bearings, ranges = sensing_matrix(px, py, ph, np.ones(len(px), bool), self.sense_range, self.fov)
            by_id = {
                n.id: (bool(sensed[0, k + 1]), float(bearings[0, k + 1]), float(ranges[0, k + 1]))
                for k, n in enumerate(placed)
            }
        out: list[Contact] = []
        for n in given:
            if n.bearing is not None and n.range is not None:  # as seen: exactly as given
                bearing, rng = n.bearing, n.range
                fov = self.fov is not None and self.fov < 2 * math.pi
                ok = (self.sense_range is None or rng <= self.sense_range) and (
                    not fov or abs(wrap(bearing - heading)) <= 0.5 * (self.fov or 0.0)
                )
            else:
                ok, bearing, rng = by_id[n.id]
            if ok:
                out.append(Contact(n.id, bearing, n.heading, rng, n.hops))
        return tuple(out)

    def _target(self, where: str, target: object, x: float, y: float) -> tuple[float, float] | None:
        if self.role == "leader":
            if target is None:
                raise ValueError(f"{where}: target: a leader needs the target's position (x, y)")
            tx, ty = _point(where, "target", target)
            return tx - x, ty - y
        if target is not None:
            raise ValueError(f"{where}: target: followers never know the target (give it to a leader)")
        return None

    def frame(
        self,
        *,
        x: float = 0.0,
        y: float = 0.0,
        heading: float = 0.0,
        neighbours: Iterable[Neighbour] = (),
        target: tuple[float, float] | None = None,
        tick: int = 0,
        time: float | None = None,
    ) -> SensorFrame:
        """The SensorFrame the world sends an agent at (x, y) with `heading` at `tick`
        (time: tick * dt unless given); `target`: where the target is (leaders only)."""
        return self._frame("frame", x, y, heading, neighbours, target, tick, time)

    def _frame(
        self,
        where: str,
        x: float,
        y: float,
        heading: float,
        neighbours: Iterable[Neighbour],
        target: object,
        tick: int,
        time: float | None,
    ) -> SensorFrame:
        tick = _integer(where, "tick", tick)
        t = tick * self.dt if time is None else _number(where, "time", time)
        contacts = self._contacts(where, x, y, heading, neighbours)
        return SensorFrame(tick, t, self.id, float(heading), contacts, self._target(where, target, x, y))

    def observation(
        self,
        *,
        x: float = 0.0,
        y: float = 0.0,
        heading: float = 0.0,
        neighbours: Iterable[Neighbour] = (),
        out: int | None = None,
        target: tuple[float, float] | None = None,
        tick: int = 0,
        time: float | None = None,
        last_u: float = 0.0,
        state: dict[str, Any] | None = None,
        search: Search | None = None,
    ) -> Observation:
        """The Observation a law gets, as the agent builds it (agents/brain.py) from the frame
        `frame(...)` would give: `out`, the id of the sensed neighbour chosen as out-neighbour
        (followers; None: nobody to follow), `last_u` the previous turn rate, `state` the law's
        own dict (a new one unless given), `search` a follower's search circle."""
        where = "observation"
        f = self._frame(where, x, y, heading, neighbours, target, tick, time)
        chosen: Contact | None = None
        if out is not None:
            _integer(where, "out", out)
            if self.role == "leader":
                raise ValueError(f"{where}: out: leaders have no out-neighbour")
            chosen = next((c for c in f.contacts if c.id == out), None)
            if chosen is None:
                sensed = ", ".join(str(c.id) for c in f.contacts) or "none"
                raise ValueError(f"{where}: out: {out} is not a neighbour the agent senses (sensed: {sensed})")
        if search is not None:
            if not isinstance(search, Search):
                raise TypeError(f"{where}: search: expected a swarm.contracts.observation.Search, got {search!r}")
            if self.role == "leader" or out is not None:
                raise ValueError(f"{where}: search: only a follower with nobody to follow (out None) searches")
        if state is not None and not isinstance(state, dict):
            raise TypeError(f"{where}: state: expected a dict, got {state!r}")
        return Observation(
            self.id,
            self.role,
            f.tick,
            f.time,
            self.dt,
            self.speed,
            f.heading,
            self.max_turn_rate,
            f.contacts,
            chosen,
            f.target,
            self.orbit_radius,
            self.sign,
            self.c1,
            self.c2,
            MappingProxyType({k: float(v) for k, v in self.params.items()}),
            {} if state is None else state,
            _number(where, "last_u", last_u),
            search,
        )

    def conf(
        self, *, n_agents: int = 2, follower_law: str = DEFAULT[FOLLOWER], leader_law: str = DEFAULT[LEADER]
    ) -> BrainConf:
        """This agent's BrainConf (what the world's join reply carries): `n_agents` caps the
        hop counts it advertises; the law names as in the scenario's [law] table."""
        a = AgentConf(
            self.id, self.role, self.speed, self.orbit_radius, self.direction, self.follow, self.max_turn_rate
        )
        sensing = SensingConf(self.selection, self.hysteresis, self.sense_range, self.fov)
        law = LawConf(follower_law, leader_law, {k: float(v) for k, v in self.params.items()})
        return BrainConf(a, GainsConf(self.c1, self.c2, DEFAULT[GAINS]), sensing, self.dt, n_agents, law)
