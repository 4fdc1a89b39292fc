"""The paper's definitions every layer reports with, in one place: angles wrapped to
(-pi, pi], the path from an agent to its leader along the chosen out-neighbours, and
the orbit radius that path promises (Theorem 1: R_i = v_i / omega_root, with
omega_root = v_L / R_L of the leader at the end of the path). Pure, scalars in plain Python,
but `wrap_array`: `wrap` for whole numpy arrays, to the bit (world/kinematics.py's headings,
the batch brains).
"""

from __future__ import annotations

import math
from typing import Any

TAU = 2.0 * math.pi


def wrap(angle: float) -> float:
    """Wrap an angle (rad) to (-pi, pi]."""
    w = math.remainder(angle, TAU)
    if w <= -math.pi:
        w += TAU
    return w


_FAST = 1.25 * TAU  # below this |angle| the remainder subtracts at most one tau


def wrap_array(angle: Any) -> Any:
    """`wrap` on a numpy array (or anything numpy takes), the same bits: exact in numpy for
    |angle| < 1.25 tau (there the remainder subtracts at most one tau, and by Sterbenz's
    lemma that subtraction is exact); larger angles go through math.remainder."""
    import numpy as np  # lazy: agent processes import this module and never load numpy

    a = np.asarray(angle, dtype=float)
    w = np.where(a > math.pi, a - TAU, np.where(a < -math.pi, a + TAU, a))
    big = np.abs(a) >= _FAST
    if big.any():
        w = np.array(w, dtype=float)
        w[big] = [math.remainder(v, TAU) if math.isfinite(v) else math.nan for v in a[big].tolist()]
    return np.where(w <= -math.pi, w + TAU, w)[()]  # a scalar for a scalar


def root_of(agent: int, out: dict[int, int | None], leaders: set[int]) -> tuple[int | None, int | None]:
    """Follow out-neighbours from `agent` to a leader: (root id, hops), (None, None) if the
    walk ends nowhere (no out-neighbour, an unknown agent) or runs round a follower-only cycle."""
    seen = set()
    cur, hops = agent, 0
    while cur not in leaders:
        nxt = out.get(cur)
        if cur in seen or nxt is None:
            return None, None
        seen.add(cur)
        cur = nxt
        hops += 1
    return cur, hops


def roots(out: dict[int, int | None], leaders: set[int]) -> dict[int, int | None]:
    """`root_of`'s root for every agent of `out`, in one pass: each agent is walked once (the
    walk of a long chain is shared by everyone on it), O(N) where N calls of root_of are O(N x depth)."""
    found: dict[int, int | None] = {}
    for start in out:
        path: list[int] = []
        on_path: set[int] = set()
        cur = start
        while True:
            if cur in found:
                root = found[cur]
                break
            if cur in leaders:
                root = cur
                break
            nxt = out.get(cur)
            if cur in on_path or nxt is None:
                root = None
                break
            on_path.add(cur)
            path.append(cur)
            cur = nxt
        for a in path:
            found[a] = root
        found.setdefault(start, root)
    return found


def expected_radius(speed: float, leader_speed: float, leader_radius: float) -> float:
    """R_i (m) of an agent of `speed` (m/s) rooted at a leader of `leader_speed` (m/s) on
    an orbit of `leader_radius` (m): it turns at the leader's omega = v_L / R_L."""
    return speed * leader_radius / leader_speed
