"""Unicycle kinematics: x' = v cos g, y' = v sin g, g' = u, with u held over the step.

Exact arc integration (not Euler): over a step of length dt with constant u the
agent moves along a circular arc (a straight line when u = 0). Written with the
sinc form, which is exact and has no cancellation when u*dt is small.
Pure numpy; works on scalars or arrays of agents alike.
"""

from __future__ import annotations

import numpy as np


def wrap(angle):
    """Wrap an angle (rad), or an array of them, to (-pi, pi]."""
    w = np.arctan2(np.sin(angle), np.cos(angle))
    return w + 2.0 * np.pi * (w <= -np.pi)


def step(x, y, heading, speed, turn_rate, dt: float):
    """Advance unicycles by dt seconds with constant turn rates.

    x, y (m), heading (rad), speed (m/s), turn_rate (rad/s): scalars or arrays of one
    shape. Returns (x, y, heading) after the step, heading wrapped to (-pi, pi].
    """
    half = 0.5 * np.asarray(turn_rate, dtype=float) * dt
    chord = np.asarray(speed, dtype=float) * dt * np.sinc(half / np.pi)  # sin(h)/h, exact at 0
    mid = heading + half
    return x + chord * np.cos(mid), y + chord * np.sin(mid), wrap(heading + 2.0 * half)
