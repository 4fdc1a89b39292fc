"""Out-neighbour selection (agents/selection.py) for many followers at once.

The rules of agents/selection.py written over arrays: a frame's contacts become a
boolean row `cand[m, i, :]` (which agents follower i of member m may choose) beside the
range row `rng[m, i, :]`; an out-neighbour is a column index, -1 for none. Every rule
here makes the same choice, tie for tie, as its scalar original:

- `nearest`: the smallest range, ties to the lowest id (selection.nearest);
- `select`: selection.select's hysteresis (keep the current one unless the nearest is
  closer than (1 - h) times its range: selection.keeps_current itself, on arrays);

sticky.Sticky itself is batched in agents/batch_sticky.py.

Pure: arrays in, arrays out; no I/O.
"""

from __future__ import annotations

import numpy as np

from swarm.agents.selection import keeps_current

NONE = -1  # no out-neighbour / no hop count / no feasible count


def nearest(cand: np.ndarray, rng: np.ndarray, ids: np.ndarray | None) -> np.ndarray:
    """(M, N) column of the nearest candidate per row of (M, N, N) `cand`, -1 if none;
    ties go to the lowest id. ids: (M, N) agent ids, or None when ids increase along
    the columns (then the first column of the smallest range is the lowest id)."""
    r = np.where(cand, rng, np.inf)
    best = r.argmin(axis=-1)
    if ids is not None:
        low = np.take_along_axis(r, best[..., None], axis=-1)
        tie = cand & (r == low)
        best = np.where(tie, ids[:, None, :], np.iinfo(np.int64).max).argmin(axis=-1)
    return np.where(cand.any(axis=-1), best, NONE)


def select(
    cand: np.ndarray, rng: np.ndarray, ids: np.ndarray | None, current: np.ndarray, hysteresis: float | np.ndarray
) -> np.ndarray:
    """selection.select after its candidate filter: the nearest candidate, or the current
    out-neighbour while it is a candidate and the nearest is not (1 - h) times closer.
    current: (M, N) columns (-1 none); hysteresis: scalar or (M, 1)."""
    best = nearest(cand, rng, ids)
    h = np.asarray(hysteresis, dtype=float)
    if not (h > 0.0).any():
        return best
    c = np.maximum(current, 0)
    cur_cand = (current >= 0) & np.take_along_axis(cand, c[..., None], axis=-1)[..., 0]
    r_best = np.take_along_axis(rng, np.maximum(best, 0)[..., None], axis=-1)[..., 0]
    r_cur = np.take_along_axis(rng, c[..., None], axis=-1)[..., 0]
    hold = (h > 0.0) & (best >= 0) & (current != best) & cur_cand & keeps_current(r_best, r_cur, h)
    return np.where(hold, current, best)
