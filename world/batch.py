"""Ground truth and sensors for many runs at once: B members (scenarios) x N agents.

`BatchWorld` is WorldCore for a batch of fault-free runs in which every agent stays in
the world: (B, N) poses, commands sanitised and latched as WorldCore.set_command does
(a non-finite turn rate refused, the agent's limit applied, hop counts outside
0..N advertised as none), one exact arc step (world/kinematics.step) for everybody.
`BatchFrames` is a tick's frames as arrays, with world/sensing.sensing_matrix's
formulas: a pair (i, j) computed alone gives the bits the whole matrix would, so the
sensing matrices are only built for the members whose followers need to look around
(agents/batch.py says what the brains ask for). Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm.contracts.frames import Contact
from swarm.contracts.vocabulary import SwitchReason
from swarm.world.core import switch_reason
from swarm.world.kinematics import step, wrap

NONE = -1


def _take(a: np.ndarray, j: np.ndarray) -> np.ndarray:
    return a[np.arange(a.shape[0])[:, None], np.maximum(j, 0)]


def sensing_matrices(x: Any, y: Any, heading: Any, sense_range: Any, fov: Any, fov_on: Any) -> Any:
    """swarm.world.sensing.sensing_matrix for M members with everybody present: (S, range),
    both (M, N, N); sense_range (M,) (inf: unlimited), fov (M,) applied where fov_on."""
    dx = x[:, None, :] - x[:, :, None]
    dy = y[:, None, :] - y[:, :, None]
    rng = np.hypot(dx, dy)
    n = x.shape[1]
    s = np.broadcast_to(~np.eye(n, dtype=bool), rng.shape).copy()
    if np.isfinite(sense_range).any():
        s &= rng <= sense_range[:, None, None]
    if fov_on.any():
        bearing = np.arctan2(dy, dx)
        s &= ~fov_on[:, None, None] | (np.abs(wrap(bearing - heading[:, :, None])) <= 0.5 * fov[:, None, None])
    return s, rng


class BatchFrames:
    """This tick's frames of every member (the protocol agents/batch.py reads)."""

    def __init__(self, w: BatchWorld):
        self.w = w
        self.heading = w.heading
        self.hops = w.hops.copy()  # what this tick's frames advertise
        self.ids, self.ids_sorted = w.ids, w.ids_sorted

    def target(self, b: np.ndarray, i: np.ndarray) -> Any:
        """(tx, ty): the target minus the position of agents (b, i) (a leader's frame)."""
        w = self.w
        return w.target[b, 0] - w.x[b, i], w.target[b, 1] - w.y[b, i]

    def offsets(self, j: Any) -> Any:
        """(dx, dy) (B, N): agent j[b, i]'s position minus agent i's."""
        w = self.w
        return _take(w.x, j) - w.x, _take(w.y, j) - w.y

    def contacts(self, b: int, i: int, sensed_row: Any, rng_row: Any) -> tuple[Contact, ...]:
        """The contacts of agent (b, i)'s frame (world/sensing.build_frames' values), from row i
        of member b's sensing matrices; bearings with numpy's arctan2, as the world's."""
        w = self.w
        j = np.flatnonzero(sensed_row)
        if not j.size:
            return ()
        x, y, ids, heading, hops = w.x[b], w.y[b], w.ids[b], self.heading[b], self.hops[b]
        bearing = np.arctan2(y[j] - y[i], x[j] - x[i])
        return tuple(
            Contact(int(ids[a]), float(bb), float(heading[a]), float(rng_row[a]), int(hops[a]))
            for a, bb in zip(j.tolist(), bearing.tolist())
        )

    def sensed_pairs(self, j: np.ndarray, b: Any = slice(None)) -> np.ndarray:
        """(B, N): agent i senses agent j[b, i] (False where j < 0); with `b`, the
        members b only (j then has their rows)."""
        w = self.w
        s = (j >= 0) & (j != np.arange(j.shape[1]))
        if w.unlimited:
            return s
        x, y, heading = w.x[b], w.y[b], w.heading[b]
        dx, dy = _take(x, j) - x, _take(y, j) - y
        if w.ranged:
            s &= np.hypot(dx, dy) <= w.sense_range[b, None]
        fov_on = w.fov_on[b]
        if fov_on.any():
            bearing = np.arctan2(dy, dx)
            s &= ~fov_on[:, None] | (np.abs(wrap(bearing - heading)) <= 0.5 * w.fov[b, None])
        return s

    def bearing_pairs(self, j: np.ndarray) -> np.ndarray:
        """(B, N): line-of-sight angle from agent i to agent j[b, i] (meaningless where j < 0)."""
        dx, dy = self.offsets(j)
        return np.arctan2(dy, dx)

    def matrices(self, m: np.ndarray) -> Any:
        """(sensed, range) (|m|, N, N) of members m."""
        w = self.w
        return sensing_matrices(w.x[m], w.y[m], w.heading[m], w.sense_range[m], w.fov[m], w.fov_on[m])


class BatchWorld:
    def __init__(self, scenarios: list):
        """scenarios: fault-free, one dt, the same number of agents."""
        n = {len(s.agents) for s in scenarios}
        if len(n) != 1 or len({s.run.dt for s in scenarios}) != 1:
            raise ValueError("a batch needs one dt and the same number of agents in every member")
        self.n = n.pop()
        rows = [s.agents for s in scenarios]

        def arr(f: Any, dtype: Any = float) -> Any:
            return np.array([[f(a) for a in row] for row in rows], dtype=dtype)

        self.ids = arr(lambda a: a.id, np.int64)
        self.ids_sorted = bool((np.diff(self.ids, axis=1) > 0).all())
        self.x, self.y, self.heading = arr(lambda a: a.x), arr(lambda a: a.y), arr(lambda a: a.heading)
        self.speed = arr(lambda a: a.speed)
        self.limit = arr(lambda a: a.max_turn_rate or math.inf)
        self.is_leader = arr(lambda a: a.role == "leader", bool)
        self.target = np.array([[s.target.x, s.target.y] for s in scenarios], dtype=float)
        self.u = np.zeros(self.x.shape)
        self.hops = np.where(self.is_leader, 0, NONE).astype(np.int64)
        self.dt = scenarios[0].run.dt
        self.tick = 0
        self.rejected = np.zeros(len(scenarios), dtype=np.int64)
        self.sense_range = np.array([s.sensing.range or math.inf for s in scenarios], dtype=float)
        self.fov = np.array([s.sensing.fov or 2 * math.pi for s in scenarios], dtype=float)
        self.fov_on = np.array([s.sensing.fov is not None and s.sensing.fov < 2 * np.pi for s in scenarios])
        self.ranged = bool(np.isfinite(self.sense_range).any())
        self.unlimited = not self.ranged and not self.fov_on.any()
        self.sticky = scenarios[0].sensing.selection == "sticky"  # one rule per batch

    def frames(self) -> BatchFrames:
        return BatchFrames(self)

    def latch(self, u: np.ndarray, hops: np.ndarray) -> np.ndarray:
        """WorldCore.set_command for everybody: (B, N) True where latched (finite)."""
        ok = np.isfinite(u)
        u = np.maximum(-self.limit, np.minimum(self.limit, u))
        hops = np.where((hops >= 0) & (hops <= self.n), hops, NONE)
        if ok.all():
            self.u, self.hops = u, hops
        else:
            self.rejected += (~ok).sum(axis=1)
            self.u, self.hops = np.where(ok, u, self.u), np.where(ok, hops, self.hops)
        return ok

    def step(self, u: np.ndarray | None = None, speed: np.ndarray | None = None) -> None:
        """One exact arc step of everybody with the latched turn rates, or with `u` and `speed`
        ((B, N): the safety filter's, swarm/offline/batch.py) instead."""
        u = self.u if u is None else u
        v = self.speed if speed is None else speed
        self.x, self.y, self.heading = step(self.x, self.y, self.heading, v, u, self.dt)
        self.tick += 1

    def switch_reason(
        self, frames: BatchFrames, b: int, i: int, old: int, new: int, pinned: int | None
    ) -> SwitchReason:
        """WorldCore.switch_reason for member b's agent in column i, columns old -> new
        (-1 none); pinned: the column of its `follow` under selection = "fixed", else None.
        Nobody leaves the world in a batch run, so that reason never comes up."""

        def in_sight() -> bool:
            j = np.full((1, self.n), NONE, dtype=np.int64)
            j[0, i] = old
            return bool(frames.sensed_pairs(j, slice(b, b + 1))[0, i])

        return switch_reason(
            sticky=self.sticky,
            new=new >= 0,
            pinned_missed=pinned is not None and new != pinned,
            old=old >= 0,
            old_left=lambda: False,
            old_in_sight=in_sight,
            old_hopless=lambda: bool(frames.hops[b, old] < 0),
        )
