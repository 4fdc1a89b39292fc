"""Follower guidance laws, looked up by name.

A follower law is a pure function of the follower's own measurements:

    law(g_i, g_j, lambda_ij, c1, c2) -> u_i

    g_i        own heading (rad)
    g_j        heading of the out-neighbour j (rad)
    lambda_ij  line-of-sight angle from i to j, world frame (rad)
    c1, c2     the scenario's [gains]
    returns    turn rate u_i (rad/s); the agent saturates it at its max_turn_rate

No range and no target position enter a follower law. A scenario names its law in
`[gains] law = "bearing"` (the paper's law, the default) or `"package.module:function"`
for a law of your own with the signature above; names resolve in swarm/contracts/laws.py.
"""

from __future__ import annotations

import math
from typing import Callable

from swarm.contracts.laws import LawError, resolve_law
from swarm.contracts.orbits import wrap


def bearing_law(g_i: float, g_j: float, lambda_ij: float, c1: float, c2: float) -> float:
    """The paper's law (Theorem 1): u_i = C1 wrap(g_j - g_i) + C2 sin(lambda_ij - g_i)."""
    return c1 * wrap(g_j - g_i) + c2 * math.sin(lambda_ij - g_i)


def make_follower_law(name: str, c1: float, c2: float) -> Callable[[float, float, float], float]:
    """Check the gains once and return u(g_i, g_j, lambda_ij) with them bound."""
    if not (math.isfinite(c1) and math.isfinite(c2)):
        raise LawError(f"gains must be finite, got c1={c1}, c2={c2}")
    law = resolve_law(name)

    def u(g_i: float, g_j: float, lambda_ij: float) -> float:
        return float(law(g_i, g_j, lambda_ij, c1, c2))

    return u
