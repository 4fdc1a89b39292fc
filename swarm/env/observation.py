"""An agent's observation as a fixed-size float32 array, and a policy on such arrays run as a
law (docs/guides/learning.md#observation).

The array is made from the `Observation` a law is given (swarm/contracts/observation.py),
which the agent builds from its sensor frame: the environment (swarm/env/parallel.py) and
the law `policy_law` wraps build it with the same function from the same observation, so a
policy sees the same numbers in training, under `swarm sim` and under `swarm up`.

Layout for K nearest contacts (`size(K)` = 18 + 5 K floats; angles in rad, relative to the
agent's own heading and wrapped to (-pi, pi]; ranges in m):

    own      0 fresh          1.0: made from this tick's frame; 0.0: no frame arrived (lost
                              or late under a network fault: the environment repeats the last
                              array and ignores the action, the last command is held)
             1 leader         1.0 leader, 0.0 follower
             2 speed          own forward speed (m/s)
             3 max_turn_rate  own turn-rate limit (rad/s); 0.0: none
             4 last_u         the turn rate commanded at the previous tick (rad/s)
             5 cos_heading    own heading, world frame
             6 sin_heading
             7 contacts       how many agents it senses this tick (all, not only the K below)
    target   8 present        leaders: 1.0; followers: 0.0 and the rest of the block 0.0
             9 range          distance to the target (m)
            10 bearing        line-of-sight angle to the target, relative
            11 orbit_radius   R of its [[agents]] entry (m)
            12 direction      +1 counter-clockwise, -1 clockwise
    out     13 present        followers: 1.0 when the selection rule chose an out-neighbour
            14 range          (the agent it steers by); else 0.0 and the block 0.0
            15 bearing        line-of-sight angle to it, relative
            16 heading        its heading, relative
            17 hops           its advertised hops to a leader (-1: none)
    contact 18 + 5 j ...      the j-th nearest contact (j = 0..K-1, by range, then id), the
                              same five fields as `out`; blocks past the last contact are 0.0
                              (present 0.0: the mask)

`FIELDS` names them ("own.fresh", ..., "contact3.range"); `index(name, k)` finds one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm.contracts.frames import Contact
from swarm.contracts.observation import Observation
from swarm.contracts.orbits import wrap

K_NEAREST = 6  # contacts in the array by default
OWN = ("fresh", "leader", "speed", "max_turn_rate", "last_u", "cos_heading", "sin_heading", "contacts")
TARGET = ("present", "range", "bearing", "orbit_radius", "direction")
CONTACT = ("present", "range", "bearing", "heading", "hops")  # the out block and each contact block
FIXED = len(OWN) + len(TARGET) + len(CONTACT)  # 18: the floats before the contacts

Policy = Callable[[np.ndarray], Any]  # observation array -> turn rate (a float, or an array of one)


def size(k: int = K_NEAREST) -> int:
    """Floats in an observation array with `k` contacts."""
    return FIXED + len(CONTACT) * k


def fields(k: int = K_NEAREST) -> list[str]:
    """The name of every float of the array, in order."""
    names = [f"own.{f}" for f in OWN] + [f"target.{f}" for f in TARGET] + [f"out.{f}" for f in CONTACT]
    for j in range(k):
        names += [f"contact{j}.{f}" for f in CONTACT]
    return names


FIELDS = fields(K_NEAREST)


def index(name: str, k: int = K_NEAREST) -> int:
    """Position of the float named `name` (e.g. "out.bearing") in an array of `k` contacts."""
    return fields(k).index(name)


def _contact(c: Contact, heading: float) -> tuple[float, float, float, float, float]:
    return (1.0, c.range, wrap(c.bearing - heading), wrap(c.heading - heading), float(c.hops))


_NONE = (0.0, 0.0, 0.0, 0.0, 0.0)


def observation_array(obs: Observation, k: int = K_NEAREST, fresh: bool = True) -> np.ndarray:
    """The float32 array of `obs` (layout in the module's docstring)."""
    g = obs.heading
    values: list[float] = [
        1.0 if fresh else 0.0,
        1.0 if obs.role == "leader" else 0.0,
        obs.speed,
        obs.max_turn_rate or 0.0,
        obs.last_u,
        math.cos(g),
        math.sin(g),
        float(len(obs.contacts)),
    ]
    if obs.target is not None:
        rng = math.hypot(obs.target[0], obs.target[1])
        bearing = wrap(math.atan2(obs.target[1], obs.target[0]) - g)
        values += [1.0, rng, bearing, obs.orbit_radius or 0.0, float(obs.direction)]
    else:
        values += _NONE
    values += _NONE if obs.out is None else _contact(obs.out, g)
    nearest = sorted(obs.contacts, key=lambda c: (c.range, c.id))[:k]
    for c in nearest:
        values += _contact(c, g)
    values += _NONE * (k - len(nearest))
    return np.array(values, dtype=np.float32)


def turn_rate(action: Any) -> float:
    """A policy's answer (or an environment action) as a float: a number or an array of one."""
    return float(np.asarray(action, dtype=float).reshape(-1)[0])


def policy_law(policy: Policy, k: int = K_NEAREST) -> Callable[[Observation], float]:
    """A law (obs -> u) that runs `policy` on the observation array: name it in a scenario
    as `[law] follower = "module:name"` (or `leader`) with `name = policy_law(policy)` at
    a module's top level. The agent saturates u at its max_turn_rate, as the environment
    does with an action."""

    def law(obs: Observation) -> float:
        return turn_rate(policy(observation_array(obs, k)))

    law.__name__ = law.__qualname__ = f"policy_law({getattr(policy, '__name__', type(policy).__name__)})"
    law.__doc__ = f"`{law.__name__}`: the policy on the observation array of {k} contacts (swarm.env)."
    return law
