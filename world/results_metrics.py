"""Pass 3 of writing a run's results by streaming (world/results_stream.py): summary.json's
figures (`Metrics`) from the arrays' .npy files read back CHUNK rows at a time, by streaming
accumulators that do exactly the arithmetic of world/metrics.py, in the same order (switch
counts, each agent's final radius, settling time, angular rate, the fault recoveries); the
follow-state seconds (`follow_counts`, `state_seconds`). Memory: the chunk read back and the
expected radii of the graphs seen (at most CACHE_MAX).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarm.contracts.orbits import expected_radius, root_of
from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.contracts.wire import FOLLOW_STATES
from swarm.world.metrics import SETTLING_BAND, _finite_or_none
from swarm.world.results_stream import NpyFiles, _chunks

CACHE_MAX = 4096  # graphs (out, alive) whose expected radii relative_errors keeps


# ------------------------------------------------------------------ pass 3: summary.json's figures


def follow_counts(follow: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """(n, len(FOLLOW_STATES)) ticks each agent was alive in each follow state, over the rows
    given ((rows, n) arrays; codes outside FOLLOW_STATES are not counted)."""
    n, k = follow.shape[1], len(FOLLOW_STATES)
    codes = follow.astype(np.int64)
    use = alive & (codes >= 0) & (codes < k)
    cells = (np.arange(n)[None, :] * k + codes)[use]
    return np.bincount(cells, minlength=n * k).reshape(n, k)


def state_seconds(counts: np.ndarray, dt: float) -> dict[str, float]:
    """summary.json's `state_s` of one follower: {follow state: seconds}, the states it was in
    (in FOLLOW_STATES order), from its row of `follow_counts` over every row but the last (a
    row's state holds over [t_k, t_k + dt); the last row is the end of the run)."""
    return {str(FOLLOW_STATES[c]): round(v * dt, 9) for c, v in enumerate(counts.tolist()) if v}


class _Switches:
    """`metrics.switch_ticks` counted as rows come: a change of out-neighbour while alive at
    both ticks counts once the agent had an out-neighbour at an earlier tick since it last
    (re)joined (tick 0 starts the first stay)."""

    def __init__(self, n: int):
        self.counts = np.zeros(n, dtype=np.int64)
        self.last_has = np.full(n, -1, dtype=np.int64)  # the last tick with an out-neighbour while alive
        self.last_join = np.zeros(n, dtype=np.int64)  # the last (re)join: 0, or a tick alive after one not
        self.prev: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, r0: int, out: np.ndarray, alive: np.ndarray) -> None:
        m = len(out)
        g = np.arange(r0, r0 + m, dtype=np.int64)[:, None]
        if self.prev is None:  # tick 0 has no tick before it: no change (and a join at 0 is last_join's 0)
            p_out, p_alive = np.vstack([out[:1], out[:-1]]), np.vstack([np.zeros_like(alive[:1]), alive[:-1]])
        else:
            p_out, p_alive = np.vstack([self.prev[0], out[:-1]]), np.vstack([self.prev[1], alive[:-1]])
        changed = (out != p_out) & alive & p_alive
        joined = alive & ~p_alive
        last_join = np.maximum(self.last_join, np.maximum.accumulate(np.where(joined, g, -1), axis=0))
        has = (out >= 0) & alive
        acc = np.maximum.accumulate(np.where(has, g, -1), axis=0)
        before = np.maximum(self.last_has, np.vstack([np.full((1, out.shape[1]), -1, np.int64), acc[:-1]]))
        self.counts += (changed & (before >= last_join)).sum(axis=0)
        self.last_has = np.maximum(self.last_has, acc[-1])
        self.last_join = last_join[-1]
        self.prev = (out[-1:].copy(), alive[-1:].copy())


class _Unwrap:
    """`np.unwrap` of a series that comes in pieces: its first value and the running sum of
    the corrections, so that the last unwrapped value is `last + sum`, bit for bit."""

    def __init__(self) -> None:
        self.first: float | None = None
        self.last: np.ndarray | None = None  # the previous piece's last value (1 element)
        self.sum: np.ndarray | None = None  # the corrections' running sum (1 element)

    def add(self, p: np.ndarray) -> None:
        if not len(p):
            return
        if self.last is None:
            self.first = p[0]
            ext = p
        else:
            ext = np.concatenate([self.last, p])
        self.last = p[-1:]
        if len(ext) < 2:
            return
        dd = np.diff(ext)
        period = 2 * math.pi
        interval_high = period / 2
        interval_low = -interval_high
        ddmod = np.mod(dd - interval_low, period) + interval_low
        np.copyto(ddmod, interval_high, where=(ddmod == interval_low) & (dd > 0))
        ph_correct = ddmod - dd
        np.copyto(ph_correct, 0, where=abs(dd) < period / 2)
        cs = ph_correct.cumsum() if self.sum is None else np.concatenate([self.sum, ph_correct]).cumsum()
        self.sum = cs[-1:]

    def span(self) -> Any:
        """theta[-1] - theta[0]."""
        assert self.last is not None and self.first is not None
        end = self.last if self.sum is None else self.last + self.sum
        return end[0] - self.first


@dataclass
class _Fault:
    spec: dict
    k0: int
    k1: int
    start: int
    stop: int  # the window err[k0:k1] is rows start..stop-1
    last_bad: int = -1  # row in the window (from its start)
    last_no_live: bool = False
    worst: float | None = None
    missed: int = 0


@dataclass
class Metrics:
    """summary.json's run figures from `NpyFiles` (pass 3): what `RunResult.summary` computes
    from whole arrays (world/recording.py, world/metrics.py), with the same arithmetic."""

    scenario: Scenario  # the run's: name, faults
    static: dict[str, np.ndarray]  # the recording's static arrays: ids, role, speed, orbit_radius, target
    events: list[dict]
    agents: dict = field(default_factory=dict)
    switches: int = 0
    faults: list = field(default_factory=list)
    sim_time: float = 0.0

    def compute(self, files: NpyFiles) -> None:
        T = files.rows
        if T == 0:
            return
        ids, roles, speeds, orbit, target = (self.static[k] for k in ("ids", "role", "speed", "orbit_radius", "target"))
        tmap = np.load(files.path("t"), mmap_mode="r")  # single values and searchsorted: a few pages
        last = {k: files.read(k, T - 1, T)[0] for k in ("x", "y", "out", "alive")}
        t0, t_end = tmap[0], tmap[-1]
        self.sim_time = float(t_end)
        # agent_metrics: the final graph, each agent's root and expected radius
        leaders = {int(i) for i, r in zip(ids, roles) if r == "leader"}
        alive_final = {int(i): bool(last["alive"][k]) for k, i in enumerate(ids)}
        outs = {
            int(i): (None if not alive_final[int(i)] or last["out"][k] < 0 else int(last["out"][k]))
            for k, i in enumerate(ids)
        }
        live_leaders = {i for i in leaders if alive_final[i]}
        col = {int(i): k for k, i in enumerate(ids)}
        window = max(0.1 * (t_end - t0), tmap[1] - t0 if T > 1 else 0.0)
        n = len(ids)
        roots: list[tuple[int | None, int | None]] = []
        expected: list[float | None] = []
        for k, i in enumerate(ids):
            i = int(i)
            root, hops = root_of(i, outs, live_leaders) if alive_final[i] else (None, None)
            roots.append((root, hops))
            expected.append(
                None
                if root is None
                else expected_radius(float(speeds[k]), float(speeds[col[root]]), float(orbit[col[root]]))
            )
        # angular_rate's window: rows k0.. (the same searchsorted on the same t)
        k0 = int(np.searchsorted(tmap, t_end - window))
        k0 = min(k0, T - 2)
        ang_from = None if k0 < 0 or T < 2 else k0
        unwraps = [_Unwrap() for _ in range(n)]
        last_out = [-1] * n  # settling: last row outside the band
        settle_t: list[Any] = [None] * n  # t just after it (row last_out + 1)
        pending = [False] * n
        final_r: list[Any] = [None] * n
        switches = _Switches(n)
        faults = self._faults(tmap) if self.scenario.faults and T > 1 else []
        rel = _RelativeErrors(ids, roles, speeds, orbit, target) if faults else None
        keys = ("t", "x", "y", "out", "alive", "follow") + (("missed",) if faults else ())
        states = np.zeros((n, len(FOLLOW_STATES)), dtype=np.int64)
        for r0, r1, c in _chunks(files, keys):
            switches.add(r0, c["out"], c["alive"])
            last_row = min(r1, T - 1) - r0  # rows before the run's last one
            if last_row > 0:
                states += follow_counts(c["follow"][:last_row], c["alive"][:last_row])
            for k in range(n):
                if ang_from is not None and r1 > ang_from:
                    a = max(ang_from - r0, 0)
                    unwraps[k].add(np.arctan2(c["y"][a:, k] - target[1], c["x"][a:, k] - target[0]))
                if pending[k]:
                    settle_t[k], pending[k] = c["t"][0], False
                R = expected[k]
                if R is None and r1 < T:  # r: for the settling time, and the final radius (last chunk)
                    continue
                r = np.hypot(c["x"][:, k] - target[0], c["y"][:, k] - target[1])
                final_r[k] = r[-1]
                if R is not None:
                    idx = np.flatnonzero(np.abs(r - R) > SETTLING_BAND * R)
                    if idx.size:
                        last_out[k] = r0 + int(idx[-1])
                        if idx[-1] + 1 < len(r):
                            settle_t[k] = c["t"][idx[-1] + 1]
                        else:
                            pending[k] = True
            if rel is not None and any(f.start < r1 and r0 < f.stop for f in faults):
                err = rel.rows(c["x"], c["y"], c["out"], c["alive"])
                for f in faults:
                    self._fault_rows(f, r0, err, c["missed"])
        # agent_metrics' dicts, key by key
        for k, i in enumerate(ids):
            i = int(i)
            root, hops = roots[k]
            R = expected[k]
            err_k = None if R is None else float(abs(final_r[k] - R))
            settle = None
            if R is not None:
                if last_out[k] == T - 1:
                    settle = None
                elif last_out[k] < 0:
                    settle = float(t0)
                else:
                    settle = float(settle_t[k])
            rate: Any
            if ang_from is None:
                rate = math.nan
            else:
                rate = float(unwraps[k].span() / (t_end - tmap[ang_from]))
            self.agents[str(i)] = {
                "role": str(roles[k]),
                "out_neighbour": outs[i],
                "root": root,
                "hops": hops,
                "final_radius": float(final_r[k]),
                "expected_radius": R,
                "radial_error": err_k,
                "relative_error": None if err_k is None or R is None else err_k / R,
                "angular_rate": _finite_or_none(rate),
                "settling_time": settle,
                "alive": alive_final[i],
            }
            self.agents[str(i)]["switches"] = int(switches.counts[k])
            if roles[k] == "follower":
                self.agents[str(i)]["state_s"] = state_seconds(states[k], self.scenario.run.dt)
        self.switches = int(sum(int(c) for c in switches.counts))
        self.faults = [self._fault_result(f, tmap) for f in faults]

    # metrics.recovery, a window at a time
    def _faults(self, tmap: Any) -> list[_Fault]:
        T = len(tmap)
        dt = float(tmap[1] - tmap[0]) if T > 1 else 1.0
        specs = [
            {"index": i, **{k: v for k, v in f.model_dump().items() if v is not None}}
            for i, f in enumerate(self.scenario.faults)
        ]
        starts = sorted(int(round(f["at"] / dt)) for f in specs)
        out = []
        for f in specs:
            k0 = int(round(f["at"] / dt))
            later = [s for s in starts if s > k0]
            k1 = min(later[0] if later else T, T)
            start, stop, _ = slice(k0, k1).indices(T)
            out.append(_Fault(f, k0, k1, start, max(stop, start)))
        return out

    @staticmethod
    def _fault_rows(f: _Fault, r0: int, err: np.ndarray, missed: np.ndarray) -> None:
        a, b = max(f.start, r0), min(f.stop, r0 + len(err))
        if a >= b:
            return
        window = err[a - r0 : b - r0]
        with np.errstate(invalid="ignore"):
            worst_row = np.nanmax(np.where(np.isnan(window), -np.inf, window), axis=1)
        bad = np.flatnonzero(~(worst_row <= SETTLING_BAND) & np.isfinite(worst_row))
        if bad.size:
            f.last_bad = a - f.start + int(bad[-1])
        if b == f.stop:
            f.last_no_live = bool(np.all(np.isnan(window), axis=1)[-1])
        finite = worst_row[np.isfinite(worst_row)]
        if finite.size:
            w = float(finite.max())
            f.worst = w if f.worst is None else max(f.worst, w)
        f.missed += int(missed[a - r0 : b - r0].sum())

    def _fault_result(self, f: _Fault, tmap: Any) -> dict:
        T = len(tmap)
        dt = float(tmap[1] - tmap[0]) if T > 1 else 1.0
        length = f.stop - f.start
        if length == 0 or (f.last_bad == length - 1) or f.last_no_live:
            rec_time = None
        else:
            rec_time = float((f.last_bad + 1) * dt) if f.last_bad >= 0 else 0.0
        return {
            **f.spec,
            "tick": f.k0,
            "window_end_time": float(tmap[f.k1 - 1]) if f.k1 > f.k0 else None,
            "recovery_time": rec_time,
            "worst_relative_error": f.worst,
            "commands_missed": f.missed,
            "switches": sum(
                1 for e in self.events if e.get("kind") == EventKind.SWITCH and f.k0 <= e.get("tick", -1) < f.k1
            ),
        }


class _RelativeErrors:
    """`metrics.relative_errors`, rows at a time."""

    def __init__(self, ids: Any, roles: Any, speeds: Any, orbit_radius: Any, target: Any) -> None:
        self.ids, self.speeds, self.orbit, self.target = ids, speeds, orbit_radius, target
        self.col = {int(i): k for k, i in enumerate(ids)}
        self.leaders = {int(i) for i, r in zip(ids, roles) if r == "leader"}
        self.cache: dict[tuple, np.ndarray] = {}

    def radii(self, out_row: np.ndarray, alive_row: np.ndarray) -> np.ndarray:
        key = (out_row.tobytes(), alive_row.tobytes())
        R = self.cache.get(key)
        if R is None:
            ids, col, N = self.ids, self.col, len(self.ids)
            live = {int(i) for i, a in zip(ids, alive_row) if a}
            o = {int(i): (int(j) if j >= 0 else None) for i, j in zip(ids, out_row)}
            R = np.full(N, np.nan)
            for i in live:
                root, _ = root_of(i, o, self.leaders & live)
                if root is not None:
                    c = col[root]
                    R[col[i]] = expected_radius(self.speeds[col[i]], self.speeds[c], self.orbit[c])
            if len(self.cache) >= CACHE_MAX:
                self.cache.clear()
            self.cache[key] = R
        return R

    def rows(self, x: np.ndarray, y: np.ndarray, out: np.ndarray, alive: np.ndarray) -> np.ndarray:
        r = np.hypot(x - self.target[0], y - self.target[1])
        err = np.empty_like(r)
        for k in range(len(r)):
            R = self.radii(out[k], alive[k])
            err[k] = np.abs(r[k] - R) / R
        return err
