"""Follower guidance laws, and how an agent gets the law it runs (docs/guides/writing-a-law.md).

A law is a function of one Observation (swarm/contracts/observation.py):

    law(obs) -> u_i   turn rate (rad/s); the agent saturates it at its max_turn_rate

A follower law sees its own heading, speed and limit, every contact it senses and the one
chosen as its out-neighbour (`obs.out`, None while it has nobody to follow: the law
decides what to do then; `search` is the built-in answer, flying `obs.search`, and
`loiter` where there is no search circle), the gains, `obs.params` and a dict `obs.state`
of its own. The paper's law is `bearing`, registered as "bearing":

    u_i = C1 wrap(g_j - g_i) + C2 sin(lambda_ij - g_i)

No range and no target position enter it. The older signature,
law(g_i, g_j, lambda_ij, c1, c2) named in `[gains] law`, still works: `make_follower_law`
binds it, and the agent searches for it. Names resolve in swarm/contracts/laws.py.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import MappingProxyType

from swarm.agents.leader import on_orbit_command
from swarm.agents.ops import SCALAR, Num, Ops
from swarm.contracts.brain_config import GainsConf, LawConf
from swarm.contracts.laws import FOLLOWER, GAINS, LEADER, LawError, follower_law_name, resolve_law
from swarm.contracts.observation import Observation

Law = Callable[[Observation], float]


def bearing_law(g_i: Num, g_j: Num, lambda_ij: Num, c1: Num, c2: Num, *, ops: Ops = SCALAR) -> Num:
    """The paper's law (Theorem 1): u_i = C1 wrap(g_j - g_i) + C2 sin(lambda_ij - g_i).

    On floats; with ops=swarm.agents.batch_maths.ARRAY, on arrays of followers (the batch
    brains): the same operations in the same order, so the same bits."""
    return c1 * ops.wrap(g_j - g_i) + c2 * ops.sin(lambda_ij - g_i)


def loiter_rate(c2: Num, last_u: Num, *, ops: Ops = SCALAR) -> Num:
    """`loiter`'s turn rate: +-C2, the sign of the last turn rate (+ after none: 0.0 or -0.0)."""
    return ops.copysign(c2, ops.where(last_u == 0.0, 1.0, last_u))


def loiter(obs: Observation) -> float:
    """A circle of radius v / C2 where it is, turning the way it last turned: neither a spin
    nor bolting off in a line (what `search` does without a search circle)."""
    return loiter_rate(obs.c2, obs.last_u)


def search(obs: Observation) -> float:
    """Nobody to steer by: fly `obs.search`, the circle about the point where it last sensed
    an agent (agents/search.py), with the leaders' orbit hold; `loiter` without one."""
    s = obs.search
    if s is None:
        return loiter(obs)
    return on_orbit_command(-s.x, -s.y, obs.heading, obs.speed, s.radius, s.direction, obs.max_turn_rate)


def bearing(obs: Observation) -> float:
    """The paper's law on an observation ("bearing", the default follower law); loiters
    while there is no out-neighbour."""
    j = obs.out
    if j is None:
        return search(obs)
    return bearing_law(obs.heading, j.heading, j.bearing, obs.c1, obs.c2)


def _check_gains(c1: float, c2: float) -> None:
    if not (math.isfinite(c1) and math.isfinite(c2)):
        raise LawError(f"gains must be finite, got c1={c1}, c2={c2}")


def make_follower_law(name: str, c1: float, c2: float) -> Callable[[float, float, float], float]:
    """A law of the older signature: check the gains once and return u(g_i, g_j, lambda_ij)
    with them bound."""
    _check_gains(c1, c2)
    law = resolve_law(name, GAINS)

    def u(g_i: float, g_j: float, lambda_ij: float) -> float:
        return float(law(g_i, g_j, lambda_ij, c1, c2))

    return u


def _older(name: str, c1: float, c2: float) -> Law:
    """law(obs) around a law of the older signature; it loiters while out is None."""
    u = make_follower_law(name, c1, c2)

    def law(obs: Observation) -> float:
        j = obs.out
        if j is None:
            return search(obs)
        return u(obs.heading, j.heading, j.bearing)

    return law


def agent_law(role: str, gains: GainsConf, law: LawConf | None) -> Law:
    """The law(obs) an agent of `role` runs: gains and law, its BrainConf's (law None: the
    built-in laws)."""
    _check_gains(gains.c1, gains.c2)
    if role == "leader":
        return resolve_law("cc" if law is None else law.leader, LEADER)
    kind, name = follower_law_name(gains.law, "bearing" if law is None else law.follower)
    if kind == GAINS:
        return _older(name, gains.c1, gains.c2)
    return resolve_law(name, FOLLOWER)


def law_params(law: LawConf | None) -> MappingProxyType[str, float]:
    """obs.params: the [law.params] numbers, read-only."""
    return MappingProxyType({} if law is None else dict(law.params))
