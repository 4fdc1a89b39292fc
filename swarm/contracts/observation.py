"""What a guidance law is given at one tick: `Observation`, one named tuple for followers
and leaders alike (docs/guides/writing-a-law.md#observation).

A law is a function of one argument,

    law(obs: Observation) -> u   (turn rate, rad/s; the agent saturates it at its
                                  max_turn_rate and holds its last u when it is NaN or inf)

named in a scenario's [law] table: `follower = "module:function"` (the paper's "bearing"
by default) and `leader = "module:function"` (the CC planner and orbit hold, "cc", by
default); `[law.params]` are its parameters. A named tuple, built once per tick by
agents/brain.py: cheap (about half a microsecond), and read-only but for `state`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

from swarm.contracts.frames import Contact


class Search(NamedTuple):
    """A searching follower's circle (`Observation.search`; agents/search.py says how it
    is kept): fly about the point (x, y) relative to own position, world frame (m), at
    `radius` (m), counter-clockwise for direction +1, clockwise for -1."""

    x: float
    y: float
    radius: float
    direction: int


class Observation(NamedTuple):
    """One agent's view at one tick. Units: m, s, rad, m/s, rad/s; angles in the world
    frame, counter-clockwise from +x."""

    id: int  # own agent id
    role: str  # "leader" | "follower"
    tick: int  # tick number (the k of t_k = k dt)
    time: float  # simulated time of the tick (s)
    dt: float  # tick length (s): the command is held over [t_k, t_k + dt)
    speed: float  # own constant forward speed (m/s)
    heading: float  # own heading g_i (rad)
    max_turn_rate: float | None  # own turn-rate limit (rad/s), None: none
    contacts: tuple[Contact, ...]  # every agent sensed this tick: id, bearing, heading, range, hops
    out: Contact | None  # followers: the chosen out-neighbour; None while loitering, and for leaders
    target: tuple[float, float] | None  # leaders: target minus own position (m); followers: None
    orbit_radius: float | None  # leaders: the orbit radius R of their spec (m)
    direction: int  # leaders: +1 counter-clockwise, -1 clockwise (their spec's `direction`)
    c1: float  # [gains] c1
    c2: float  # [gains] c2
    params: Mapping[str, float]  # [law.params], read-only
    state: dict  # this agent's own dict, kept between calls (fresh when its brain is new)
    last_u: float  # the turn rate this agent commanded at the previous tick (0.0 at first)
    # followers with nobody to steer by (out None, selection "sticky"): the search circle to
    # fly, about the point where it last sensed an agent (agents/search.py); None otherwise
    search: Search | None = None

    @property
    def target_range(self) -> float | None:
        """Leaders: distance to the target (m)."""
        return None if self.target is None else math.hypot(self.target[0], self.target[1])

    @property
    def target_bearing(self) -> float | None:
        """Leaders: line-of-sight angle to the target, world frame (rad)."""
        return None if self.target is None else math.atan2(self.target[1], self.target[0])
