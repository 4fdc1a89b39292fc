"""Unicycle kinematics: x' = v cos g, y' = v sin g, g' = u, with u held over the step.

Exact arc integration (not Euler): over a step of length dt with constant u the
agent moves along a circular arc (a straight line when u = 0). Written with the
sinc form, which is exact and has no cancellation when u*dt is small.

`step` works on numpy arrays (or scalars) of agents; `step_one` is the same for one
agent on Python floats, to the bit (np.sin, np.cos and math's agree, and the headings
are wrapped by swarm.contracts.orbits.wrap, whose array version is exact): a few agents
are stepped faster one by one than by numpy's dozen calls, each of which costs
microseconds in a process whose caches the other agents' processes keep cold.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm.contracts.orbits import wrap as _wrap_one
from swarm.contracts.orbits import wrap_array

_EPS = float(np.finfo(float).eps)  # np.sinc's stand-in for 0


wrap = wrap_array  # an angle (rad), or an array of them, wrapped to (-pi, pi]


def step(x: Any, y: Any, heading: Any, speed: Any, turn_rate: Any, dt: float) -> Any:
    """Advance unicycles by dt seconds with constant turn rates.

    x, y (m), heading (rad), speed (m/s), turn_rate (rad/s): scalars or arrays of one
    shape. Returns (x, y, heading) after the step, heading wrapped to (-pi, pi].
    """
    half = 0.5 * np.asarray(turn_rate, dtype=float) * dt
    chord = np.asarray(speed, dtype=float) * dt * np.sinc(half / np.pi)  # sin(h)/h, exact at 0
    mid = heading + half
    return x + chord * np.cos(mid), y + chord * np.sin(mid), wrap(heading + 2.0 * half)


def step_one(
    x: float, y: float, heading: float, speed: float, turn_rate: float, dt: float
) -> tuple[float, float, float]:
    """`step` for one agent on Python floats, with the same bits (NaN where `step` gives NaN:
    a turn rate so large that the angles overflow, where math's functions would raise)."""
    half = 0.5 * turn_rate * dt
    if not math.isfinite(half):
        return math.nan, math.nan, math.nan
    a = math.pi * (half / math.pi)  # np.sinc(half / pi), step by step
    if a == 0.0:
        a = _EPS
    chord = speed * dt * (math.sin(a) / a)
    mid, g = heading + half, heading + 2.0 * half
    c, s = (math.cos(mid), math.sin(mid)) if math.isfinite(mid) else (math.nan, math.nan)
    return x + chord * c, y + chord * s, _wrap_one(g) if math.isfinite(g) else math.nan
