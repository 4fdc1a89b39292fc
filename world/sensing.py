"""Simulated sensors: who senses whom, and each agent's own sensor frame.

A frame holds only what the agent's sensors give it (paper, section "Main Results"):
for every agent it can sense, the line-of-sight angle lambda_ij, that agent's heading
and a range (used only to rank candidates), plus its own heading; leaders also get
the target's position relative to themselves. Pure numpy, no I/O.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm.contracts.frames import Contact, SensorFrame
from swarm.world.kinematics import wrap

__all__ = [
    "Contact",
    "SensorFrame",
    "sensing_matrix",
    "sensing_pairs",
    "sensing_grid",
    "pairs_matrices",
    "build_frames",
    "GRID_MIN_AGENTS",
]

# With a sensing range, from this many agents the world finds who senses whom through a grid
# (`sensing_grid`: O(N k), k the agents in sight) instead of every pair (`sensing_matrix`,
# O(N^2)). In a tick (caches cold) the grid's 30 numpy calls cost as much as every pair's
# dozen up to about 100 agents, and 2.5x less from 200 (docs/benchmarks.md#scaling).
GRID_MIN_AGENTS = 128
# The grid's cells are this much wider than the range, so that every pair within range lies
# in neighbouring cells whatever the rounding of the cell numbers (their relative error is
# below 2^-28 while the grid spans at most GRID_MAX_CELLS cells a side).
GRID_MARGIN = 1.0 + 1e-6
GRID_MAX_CELLS = 1 << 24


def sensing_matrix(x: Any, y: Any, heading: Any, present: Any, sense_range: float | None, fov: float | None) -> Any:
    """The reference: every pair. Boolean (N, N) matrix S with S[i, j] true when agent i senses agent j.

    present: (N,) bool, agents that are in the world. sense_range (m) or None for
    unlimited; fov: full field of view (rad) centred on the heading, or None.
    Also returns the bearing (N, N) and range (N, N) matrices. Bearings are computed only
    for the pairs within range (NaN elsewhere): with a sensing range the arctangents, the
    costliest part, grow with the pairs sensed rather than with N^2.
    """
    dx = x[None, :] - x[:, None]
    dy = y[None, :] - y[:, None]
    rng = np.hypot(dx, dy)
    s = present[:, None] & present[None, :]
    np.fill_diagonal(s, False)
    if sense_range is None:
        bearing = np.arctan2(dy, dx)
    else:
        s &= rng <= sense_range
        bearing = np.full(rng.shape, np.nan)
        bearing[s] = np.arctan2(dy[s], dx[s])
    if fov is not None and fov < 2 * np.pi:
        i, j = np.nonzero(s)
        s[i, j] = np.abs(wrap(bearing[i, j] - heading[i])) <= 0.5 * fov
    return s, bearing, rng


def sensing_pairs(x: Any, y: Any, heading: Any, present: Any, sense_range: float, fov: float | None) -> Any:
    """Who senses whom with a sensing range, through a uniform grid of cells a range wide:
    (i, j, bearing, range) arrays of the sensed pairs (agent i senses agent j), sorted by i,
    then j. The same pairs and the same bits as `sensing_matrix` (S, and its bearing and
    range where S): the same numpy operations on the same numbers, but only on the pairs
    in neighbouring cells (a superset of those within range), so the cost grows as N x the
    agents in sight rather than N^2. Falls back to `sensing_matrix` where a grid does not
    fit (positions not finite, a range of 0, a swarm more than GRID_MAX_CELLS ranges wide)."""
    n = len(x)
    idx = np.flatnonzero(present)
    m = len(idx)
    px, py = (x, y) if m == n else (x[idx], y[idx])
    cell = float(sense_range) * GRID_MARGIN
    if m < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0), np.zeros(0)
    x0, y0 = px.min(), py.min()
    span = max(px.max() - x0, py.max() - y0)
    if not (cell > 0 and np.isfinite(span) and span / cell < GRID_MAX_CELLS):
        s, bearing, rng = sensing_matrix(x, y, heading, present, sense_range, fov)
        i, j = np.nonzero(s)
        return i, j, bearing[i, j], rng[i, j]
    cx = ((px - x0) / cell).astype(np.int64)  # floor: the numbers are >= 0
    cy = ((py - y0) / cell).astype(np.int64)
    w = int(cy.max()) + 3  # cell (cx, cy) has key cx * w + cy; cy - 1 and cy + 1 stay in its column
    key = cx * w + cy
    order = np.argsort(key, kind="stable")
    skey = key[order]
    q = key[:, None] + np.array([-w, 0, w])  # the three columns of neighbouring cells, rows cy - 1 .. cy + 1
    lo = np.searchsorted(skey, q - 1, "left").ravel()
    cnt = np.searchsorted(skey, q + 1, "right").ravel() - lo
    # the candidate pairs (a, b) as indices of px, py: a ascending, b in cell order
    a = np.repeat(np.arange(m), cnt.reshape(m, 3).sum(axis=1))
    b = order[np.arange(len(a)) - np.repeat(np.cumsum(cnt) - cnt - lo, cnt)]
    dx = px[b] - px[a]  # x[j] - x[i], as in sensing_matrix
    dy = py[b] - py[a]
    rng = np.hypot(dx, dy)
    near = (rng <= sense_range) & (a != b)
    a, b, rng = a[near], b[near], rng[near]
    bearing = np.arctan2(dy[near], dx[near])
    if m != n:
        a, b = idx[a], idx[b]
    if fov is not None and fov < 2 * np.pi:
        seen = np.abs(wrap(bearing - heading[a])) <= 0.5 * fov
        a, b, bearing, rng = a[seen], b[seen], bearing[seen], rng[seen]
    o = np.argsort(a * n + b)
    return a[o], b[o], bearing[o], rng[o]


def pairs_matrices(n: int, i: Any, j: Any, bearing: Any, rng: Any) -> Any:
    """(S, bearing, range) (N, N) matrices from sensed pairs: S true at the pairs, bearing and
    range there (NaN and inf at every pair not sensed)."""
    s = np.zeros((n, n), dtype=bool)
    s[i, j] = True
    b = np.full((n, n), np.nan)
    b[i, j] = bearing
    r = np.full((n, n), np.inf)
    r[i, j] = rng
    return s, b, r


def sensing_grid(x: Any, y: Any, heading: Any, present: Any, sense_range: float, fov: float | None) -> Any:
    """`sensing_matrix` through the grid (`sensing_pairs`): the same S, and the same bearing
    and range wherever S; NaN and inf elsewhere (pairs not sensed, whose values no frame
    carries)."""
    return pairs_matrices(len(x), *sensing_pairs(x, y, heading, present, sense_range, fov))


def build_frames(
    tick: int,
    time: Any,
    ids: Any,
    x: Any,
    y: Any,
    heading: Any,
    present: Any,
    receivers: Any,
    is_leader: Any,
    target: Any,
    sense_range: Any = None,
    fov: Any = None,
    hops: Any = None,
    matrices: Any = None,
) -> dict[int, SensorFrame]:
    """One SensorFrame per receiver index (agents that need a frame this tick).

    hops: (N,) hop counts the agents last advertised (-1 none); the world relays them
    like a local broadcast that reaches exactly the agents that sense the sender.
    matrices: this tick's sensing_matrix result if already computed.
    """
    s, bearing, rng = matrices or sensing_matrix(x, y, heading, present, sense_range, fov)
    if hops is None:
        hops = np.full(len(ids), -1)
    frames: dict[int, SensorFrame] = {}
    # Python lists once per tick (the same ints and floats as int()/float() of each element)
    id_l, heading_l, hops_l = np.asarray(ids).tolist(), np.asarray(heading).tolist(), np.asarray(hops).tolist()
    tick, time = int(tick), float(time)
    # the sensed pairs once, row by row (receiver i's: ks[i] to ks[i + 1]), with their bearings and ranges
    row, col = np.nonzero(s)
    ks = np.searchsorted(row, np.arange(len(id_l) + 1)).tolist()
    j_l, b_l, r_l = col.tolist(), bearing[row, col].tolist(), rng[row, col].tolist()
    for i in receivers:
        contacts = tuple(
            [
                Contact(id_l[j], b_l[k], heading_l[j], r_l[k], hops_l[j])
                for k, j in zip(range(ks[i], ks[i + 1]), j_l[ks[i] : ks[i + 1]])
            ]
        )
        tgt = (float(target[0] - x[i]), float(target[1] - y[i])) if is_leader[i] else None
        frames[id_l[i]] = SensorFrame(tick, time, id_l[i], heading_l[i], contacts, tgt)
    return frames
