"""A synthetic run directory with the exact trajectory.npz / summary.json layout (the plot and
layout tests read it)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swarm.contracts.vocabulary import EventKind, FollowState
from swarm.contracts.wire import FOLLOW_STATES


def make_run(
    run_dir: Path,
    *,
    ticks: int = 600,
    dt: float = 0.01,
    n_leaders: int = 1,
    n_followers: int = 2,
    drop: tuple[int, int] | None = (1, 300),  # (follower index, tick) that drops
    events: bool = True,
    follow: bool = True,
) -> Path:
    """Write a synthetic run dir with the exact trajectory.npz / summary.json layout.

    Leaders orbit the target at r = 10; followers spiral in to r = 10 * speed ratio.
    Follower k follows agent k-1 (the first follows the first leader). Followers' follow
    states: acquire for the first tenth of the run, then keep, with a stretch of coast and
    one of search for the first follower; follow False: no `follow` array (an older run).
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    n = n_leaders + n_followers
    nt = ticks + 1
    t = np.arange(nt) * dt
    target = np.array([2.0, -1.0])
    ids = np.arange(1, n + 1, dtype=np.int64)
    role = np.array(["leader"] * n_leaders + ["follower"] * n_followers)
    speed = np.array([2.0] * n_leaders + [1.5 - 0.02 * k for k in range(n_followers)])
    orbit = np.array([10.0] * n_leaders + [np.nan] * n_followers)
    expected = np.where(np.isnan(orbit), 10.0 * speed / 2.0, orbit)
    # one extra sample so the heading comes from forward differences
    ts = np.arange(nt + 1) * dt
    xs = np.empty((nt + 1, n))
    ys = np.empty((nt + 1, n))
    for j in range(n):
        r0 = expected[j] if j < n_leaders else 18.0 + j
        r = expected[j] + (r0 - expected[j]) * np.exp(-ts / 1.5)
        phase = 2 * np.pi * j / n
        ang = phase + speed[j] / expected[j] * ts
        xs[:, j] = target[0] + r * np.cos(ang)
        ys[:, j] = target[1] + r * np.sin(ang)
    x, y = xs[:-1].copy(), ys[:-1].copy()
    heading = np.unwrap(np.arctan2(np.diff(ys, axis=0), np.diff(xs, axis=0)), axis=0)
    u = np.full((nt, n), np.nan)
    u[:-1] = np.diff(heading, axis=0) / dt
    out = np.full((nt, n), -1, dtype=np.int64)
    for j in range(n_leaders, n):
        out[:, j] = ids[j - 1] if j > n_leaders else ids[0]
    alive = np.ones((nt, n), dtype=bool)
    codes = {s: k for k, s in enumerate(FOLLOW_STATES)}
    states = np.zeros((nt, n), dtype=np.int8)
    states[:, n_leaders:] = codes[FollowState.KEEP]
    states[: nt // 10, n_leaders:] = codes[FollowState.ACQUIRE]
    if n_followers:
        states[nt // 3 : nt // 3 + nt // 20, n_leaders] = codes[FollowState.COAST]
        states[nt // 3 + nt // 20 : nt // 3 + nt // 10, n_leaders] = codes[FollowState.SEARCH]
    summary_events = []
    if drop is not None and drop[1] < nt:
        fk, tick = drop
        j = n_leaders + fk
        alive[tick:, j] = False
        out[tick:, j] = -1
        states[tick:, j] = 0
        u[tick:, j] = np.nan
        x[tick:, j] = x[tick, j]
        y[tick:, j] = y[tick, j]
        summary_events.append(
            {
                "tick": tick,
                "time": tick * dt,
                "agent": int(ids[j]),
                "kind": EventKind.DROP,
                "reason": "liveliness token lost",
            }
        )
    if events:
        summary_events.insert(0, {"tick": 0, "time": 0.0, "agent": 1, "kind": EventKind.JOIN})
        summary_events.append({"tick": 50, "time": 0.5, "agent": 3, "kind": EventKind.SWITCH, "from": 1, "to": 2})
    np.savez(
        run_dir / "trajectory.npz",
        **({"follow": states} if follow else {}),
        ids=ids,
        role=role,
        speed=speed,
        orbit_radius=orbit,
        target=target,
        dt=np.float64(dt),
        t=t,
        x=x,
        y=y,
        heading=heading,
        u=u,
        out=out,
        alive=alive,
    )
    summary = {
        "scenario": "synthetic",
        "converged": True,
        "ticks": ticks,
        "sim_time": ticks * dt,
        "agents": {
            str(int(ids[j])): {
                "role": str(role[j]),
                "out_neighbour": None if j < n_leaders else int(out[0, j]),
                "root": 1,
                "final_radius": float(expected[j]),
                "expected_radius": float(expected[j]),
                "alive": bool(alive[-1, j]),
            }
            for j in range(n)
        },
        "events": summary_events,
        "faults": [{"tick": 200, "time": 2.0, "kind": "kill", "agent": 3}],
    }
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir
