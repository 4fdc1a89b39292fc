"""Out-neighbour selection (agents/selection.py) for many followers at once.

The rules of agents/selection.py written over arrays: a frame's contacts become a
boolean row `cand[m, i, :]` (which agents follower i of member m may choose) beside the
range row `rng[m, i, :]`; an out-neighbour is a column index, -1 for none. Every rule
here makes the same choice, tie for tie, as its scalar original:

- `nearest`: the smallest range, ties to the lowest id (selection.nearest);
- `select`: selection.select's hysteresis (keep the current one unless the nearest is
  closer than (1 - h) times its range);
- `BatchSticky`: selection.Sticky's state machine, one row per follower.

Pure: arrays in, arrays out; no I/O.
"""

from __future__ import annotations

import numpy as np

from agents.batch_maths import take

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


def select(cand: np.ndarray, rng: np.ndarray, ids, current: np.ndarray, hysteresis) -> np.ndarray:
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
    hold = (h > 0.0) & (best >= 0) & (current != best) & cur_cand & (r_best > (1.0 - h) * r_cur)
    return np.where(hold, current, best)


class BatchSticky:
    """selection.Sticky for (B, N) followers (rows of leaders are never used).

    State per row, as Sticky keeps it: out (column), committed, acquired, feasible
    (-1: None), waited, unrooted_ticks. A tick is two calls: `keep` on every row (a
    committed follower that still senses its rooted out-neighbour keeps it: no sensing
    matrix needed), then `choose` on the members that have a row left to decide.
    """

    def __init__(self, shape: tuple[int, int], wait_ticks: int, drain_ticks: int):
        self.wait_ticks, self.drain_ticks = wait_ticks, drain_ticks
        self.out = np.full(shape, NONE, dtype=np.int64)
        self.committed = np.zeros(shape, dtype=bool)
        self.acquired = np.zeros(shape, dtype=bool)
        self.feasible = np.full(shape, NONE, dtype=np.int64)
        self.waited = np.zeros(shape, dtype=np.int64)
        self.unrooted = np.zeros(shape, dtype=np.int64)

    def keep(self, sensed_out: np.ndarray, hops: np.ndarray) -> np.ndarray:
        """Sticky.choose's first step on every row: (B, N) True where the committed
        out-neighbour is sensed and rooted (kept, feasible updated); a committed row that
        lost it is uncommitted here, as Sticky does before looking for another."""
        h_out = take(hops, self.out)
        kept = self.committed & sensed_out & (h_out >= 0)
        self.feasible = np.where(kept, np.minimum(self.feasible, h_out + 1), self.feasible)
        lost = self.committed & ~kept
        self.committed &= ~lost
        self.unrooted[lost] = 0
        return kept

    def choose(self, m: np.ndarray, rows: np.ndarray, sensed: np.ndarray, rng: np.ndarray,
               hops: np.ndarray, ids) -> tuple[np.ndarray, np.ndarray]:
        """The rest of Sticky.choose for the rows `rows` (|m|, N) of members m, whose
        sensing matrices are `sensed`, `rng` (|m|, N, N) and hop counts `hops` (|m|, N):
        (choice columns, rooted) for those members; other rows' values are not used."""
        feasible, unrooted = self.feasible[m], self.unrooted[m]
        feasible = np.where(rows & (feasible >= 0) & (unrooted >= self.drain_ticks), NONE, feasible)
        hj = hops[:, None, :]
        fz = feasible[..., None]
        best = nearest(sensed & (hj >= 0) & ((fz < 0) | (hj < fz)), rng, ids)
        none = rows & (best < 0)
        waiting = rows & (best >= 0) & ~self.acquired[m] & (self.waited[m] < self.wait_ticks)
        if waiting.any():
            first = nearest(sensed, rng, ids)
            waiting &= (first >= 0) & (first != best)
        commit = rows & (best >= 0) & ~waiting
        h_best = take(hops, best) + 1
        self.feasible[m] = np.where(commit, np.where(feasible < 0, h_best, np.minimum(feasible, h_best)),
                                    feasible)
        self.unrooted[m] = np.where(none, unrooted + 1, np.where(commit, 0, unrooted))
        self.waited[m] += waiting
        self.out[m] = np.where(rows, best, self.out[m])
        self.committed[m] |= commit
        self.acquired[m] |= commit
        return best, commit
