"""Metrics of a run, from its recorded ground truth. Pure numpy.

- expected radius R_i = v_i / omega_root, omega_root = v_L / R_L of the leader L at
  the end of agent i's path in the final communication graph (paper, Theorem 1);
- radial error |r_i(T) - R_i| (m) at the end of the run;
- angular rate about the target (rad/s, ccw positive) over the last part of the run;
- settling time: the earliest time after which |r_i - R_i| <= band * R_i for good;
- switches: how often a follower changed its out-neighbour while alive (its first choice
  after joining is not a switch, nor are the ticks before it with none; a later change to
  or from "none", searching, is).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm.contracts.orbits import expected_radius, root_of
from swarm.contracts.vocabulary import EventKind

SETTLING_BAND = 0.02  # 2% band
CONVERGED_TOL = 0.01  # a run has converged when every live agent is within 1% of R_i


def switch_ticks(out: np.ndarray, alive: np.ndarray) -> list[np.ndarray]:
    """Per column of the (T, N) `out` / `alive` arrays: the ticks k at which the agent's
    out-neighbour differs from tick k - 1 while it was alive at both ticks, once it has
    made its first choice since it (re)joined: ticks with no out-neighbour before that
    first choice, and the first choice itself, are not switches."""
    if len(out) < 2:
        return [np.zeros(0, dtype=np.int64) for _ in range(out.shape[1] if out.ndim == 2 else 0)]
    changed = (out[1:] != out[:-1]) & alive[1:] & alive[:-1]
    result = []
    for j in range(out.shape[1]):
        ks = np.flatnonzero(changed[:, j]) + 1
        if ks.size:
            # chose[k]: some tick since the last (re)join up to k had an out-neighbour
            joined = np.cumsum(np.concatenate(([True], alive[1:, j] & ~alive[:-1, j])))
            has = (out[:, j] >= 0) & alive[:, j]
            first = np.full(joined[-1] + 1, len(out))
            for seg in np.unique(joined):
                idx = np.flatnonzero(has & (joined == seg))
                if idx.size:
                    first[seg] = idx[0]
            ks = ks[ks > first[joined[ks]]]
        result.append(ks)
    return result


def settling_time(t: np.ndarray, r: np.ndarray, R: float, band: float = SETTLING_BAND) -> float | None:
    """Earliest t after which |r - R| stays within band * R; None if it ends outside."""
    outside = np.abs(r - R) > band * R
    if outside[-1]:
        return None
    idx = np.flatnonzero(outside)
    return float(t[0]) if idx.size == 0 else float(t[min(idx[-1] + 1, len(t) - 1)])


def angular_rate(t: np.ndarray, x: np.ndarray, y: np.ndarray, target: Any, window: float) -> float:
    """Mean angular rate about the target (rad/s) over the last `window` seconds."""
    k0 = int(np.searchsorted(t, t[-1] - window))
    k0 = min(k0, len(t) - 2)
    if k0 < 0 or len(t) < 2:
        return math.nan
    theta = np.unwrap(np.arctan2(y[k0:] - target[1], x[k0:] - target[0]))
    return float((theta[-1] - theta[0]) / (t[-1] - t[k0]))


def agent_metrics(
    *,
    ids: Any,
    roles: Any,
    speeds: Any,
    orbit_radius: Any,
    t: Any,
    x: Any,
    y: Any,
    alive: Any,
    out_final: Any,
    target: Any,
    window: float | None = None,
    switches: Any = None,
) -> dict[str, dict]:
    """Per-agent metrics keyed by str(id), as written to summary.json.

    switches: (N,) switch counts (see `switch_ticks`), or None to leave them out."""
    leaders = {int(i) for i, r in zip(ids, roles) if r == "leader"}
    alive_final = {int(i): bool(alive[-1, k]) for k, i in enumerate(ids)}
    out = {
        int(i): (None if not alive_final[int(i)] or out_final[k] < 0 else int(out_final[k])) for k, i in enumerate(ids)
    }
    # Dead leaders do not root anybody.
    live_leaders = {i for i in leaders if alive_final[i]}
    col = {int(i): k for k, i in enumerate(ids)}
    if window is None:
        window = max(0.1 * (t[-1] - t[0]), t[1] - t[0] if len(t) > 1 else 0.0)
    result: dict[str, dict] = {}
    for k, i in enumerate(ids):
        i = int(i)
        r = np.hypot(x[:, k] - target[0], y[:, k] - target[1])
        root, hops = root_of(i, out, live_leaders) if alive_final[i] else (None, None)
        expected: float | None = None
        err: float | None = None
        settle = None
        if root is not None:
            c = col[root]
            expected = expected_radius(float(speeds[k]), float(speeds[c]), float(orbit_radius[c]))
            err = float(abs(r[-1] - expected))
            settle = settling_time(t, r, expected)
        result[str(i)] = {
            "role": str(roles[k]),
            "out_neighbour": out[i],
            "root": root,
            "hops": hops,
            "final_radius": float(r[-1]),
            "expected_radius": expected,
            "radial_error": err,
            "relative_error": None if err is None or expected is None else err / expected,
            "angular_rate": _finite_or_none(angular_rate(t, x[:, k], y[:, k], target, window)),
            "settling_time": settle,
            "alive": alive_final[i],
        }
        if switches is not None:
            result[str(i)]["switches"] = int(switches[k])
    return result


def _finite_or_none(v: float) -> float | None:
    return v if math.isfinite(v) else None


def converged(agents: dict[str, dict], tol: float = CONVERGED_TOL) -> bool:
    """Every live agent has a root and ends within tol * R_i of its expected radius."""
    live = [a for a in agents.values() if a["alive"]]
    return bool(live) and all(a["relative_error"] is not None and a["relative_error"] < tol for a in live)


def relative_errors(
    *, ids: Any, roles: Any, speeds: Any, orbit_radius: Any, x: Any, y: Any, alive: Any, out: Any, target: Any
) -> np.ndarray:
    """(T, N) relative radial error |r - R_i| / R_i per tick, with R_i from that tick's graph
    (NaN where the agent is not alive or has no path to a live leader)."""
    T, N = x.shape
    col = {int(i): k for k, i in enumerate(ids)}
    leaders = {int(i) for i, r in zip(ids, roles) if r == "leader"}
    r = np.hypot(x - target[0], y - target[1])
    err = np.full((T, N), np.nan)
    cache: dict[tuple, np.ndarray] = {}
    for k in range(T):
        key = (out[k].tobytes(), alive[k].tobytes())
        R = cache.get(key)
        if R is None:
            live = {int(i) for i, a in zip(ids, alive[k]) if a}
            o = {int(i): (int(j) if j >= 0 else None) for i, j in zip(ids, out[k])}
            R = np.full(N, np.nan)
            for i in live:
                root, _ = root_of(i, o, leaders & live)
                if root is not None:
                    c = col[root]
                    R[col[i]] = expected_radius(speeds[col[i]], speeds[c], orbit_radius[c])
            cache[key] = R
        err[k] = np.abs(r[k] - R) / R
    return err


def recovery(
    faults: list[dict],
    t: np.ndarray,
    err: np.ndarray,
    missed: np.ndarray,
    events: list[dict],
    band: float = SETTLING_BAND,
) -> list[dict]:
    """Per scripted fault (dicts with at, kind, agent...): the time from the fault until every
    live agent's radial error is back inside the band for good (up to the next fault, or the
    end), the worst relative error meanwhile, commands missed and neighbour switches."""
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    starts = sorted(int(round(f["at"] / dt)) for f in faults)
    out = []
    for f in faults:
        k0 = int(round(f["at"] / dt))
        later = [s for s in starts if s > k0]
        k1 = min(later[0] if later else len(t), len(t))
        window = err[k0:k1]
        with np.errstate(invalid="ignore"):
            worst_row = np.nanmax(np.where(np.isnan(window), -np.inf, window), axis=1) if len(window) else np.array([])
        bad = np.flatnonzero(~(worst_row <= band) & np.isfinite(worst_row)) if len(window) else np.array([])
        no_live = np.all(np.isnan(window), axis=1) if len(window) else np.array([])
        if len(window) == 0 or (len(bad) and bad[-1] == len(window) - 1) or (len(no_live) and no_live[-1]):
            rec_time = None  # still outside the band when the window closed
        else:
            rec_time = float((bad[-1] + 1) * dt) if len(bad) else 0.0
        finite = worst_row[np.isfinite(worst_row)] if len(window) else np.array([])
        out.append(
            {
                **f,
                "tick": k0,
                "window_end_time": float(t[k1 - 1]) if k1 > k0 else None,
                "recovery_time": rec_time,
                "worst_relative_error": float(finite.max()) if finite.size else None,
                "commands_missed": int(missed[k0:k1].sum()),
                "switches": sum(
                    1 for e in events if e.get("kind") == EventKind.SWITCH and k0 <= e.get("tick", -1) < k1
                ),
            }
        )
    return out
