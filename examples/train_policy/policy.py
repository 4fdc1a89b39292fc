"""A small parametrised policy and the law that runs it (docs/guides/learning.md).

    u = k1 * out.heading + k2 * sin(out.bearing)   while the agent has an out-neighbour
    u = k2                                          while it has none (a slow circle)

with out.heading and out.bearing the out-neighbour's heading and line-of-sight angle
relative to the agent's own heading (swarm.env observation layout): the paper's bearing
law with its two gains as parameters. `law` runs it with the gains in gains.json next to
this file (INITIAL without one): scenario.toml names it, `[law] follower = "policy:law"`,
so `swarm sim` and `swarm up` run the trained policy unchanged.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from swarm.env import index, policy_law

GAINS_FILE = Path(__file__).with_name("gains.json")
INITIAL = (0.2, 0.1)  # (k1, k2) before training
OUT, HEADING, BEARING = index("out.present"), index("out.heading"), index("out.bearing")


def gains_policy(k1: float, k2: float) -> Callable[[np.ndarray], float]:
    """The policy of gains (k1, k2): observation array -> turn rate (rad/s)."""

    def policy(a: np.ndarray) -> float:
        if a[OUT] == 0.0:
            return k2
        return k1 * float(a[HEADING]) + k2 * math.sin(float(a[BEARING]))

    return policy


def load_gains(path: Path = GAINS_FILE) -> tuple[float, float]:
    """(k1, k2) from a gains file written by train.py; INITIAL when there is none."""
    if not path.exists():
        return INITIAL
    k = json.loads(path.read_text())["gains"]
    return float(k[0]), float(k[1])


POLICY = gains_policy(*load_gains())
law = policy_law(POLICY)  # the follower law scenario.toml names
