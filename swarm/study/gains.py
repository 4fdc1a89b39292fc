"""The gains study of `swarm study gains` (swarm/study/swarms.py has the swarms study): one
follower behind a leader that is already on its orbit (omega = 1 rad/s, R_L = v_L), for a
grid of (C1, C2) and follower/out-neighbour speed ratios, a few random starts each:
where does the law settle, and how fast? Jobs, the worker (`run_gain`, one run through
`swarm sim`'s per-agent engine) and the summary are pure functions of their arguments.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from swarm.contracts.scenario import Scenario, parse_scenario
from swarm.offline.sim import run_sim
from swarm.world.metrics import SETTLING_BAND, settling_time


@dataclass(frozen=True)
class GainJob:
    c1: float
    c2: float
    ratio: float  # follower speed / leader speed
    start: int  # which random start (seeded)
    duration: float = 300.0
    dt: float = 0.05


def pair_scenario(job: GainJob) -> Scenario:
    """A leader on its orbit (R = v_L = 20 m, omega = 1 rad/s, ccw, starting on it) and one
    follower at a random pose within 3 R of the target."""
    rng = np.random.default_rng([job.start, 7919])
    v_l = 20.0
    r = rng.uniform(0.2, 3.0) * v_l
    phi = rng.uniform(-math.pi, math.pi)
    return parse_scenario(
        {
            "name": "pair",
            "run": {"dt": job.dt, "duration": job.duration},
            "gains": {"c1": job.c1, "c2": job.c2},
            "sensing": {"selection": "fixed"},
            "agents": [
                {
                    "id": 1,
                    "role": "leader",
                    "x": v_l,
                    "y": 0.0,
                    "heading": math.pi / 2,
                    "speed": v_l,
                    "orbit_radius": v_l,
                },
                {
                    "id": 2,
                    "role": "follower",
                    "x": r * math.cos(phi),
                    "y": r * math.sin(phi),
                    "heading": float(rng.uniform(-math.pi, math.pi)),
                    "speed": job.ratio * v_l,
                    "follow": 1,
                },
            ],
        },
        "gain pair",
    )


def run_gain(job: GainJob) -> dict:
    """Worker: the pair's follower settling time (s; nan if it never settles)."""
    return gain_row(job, run_sim(pair_scenario(job)))


def gain_row(job: GainJob, res) -> dict:
    a = res.recorder.arrays()
    r = np.hypot(a["x"][:, 1], a["y"][:, 1])
    settle = settling_time(a["t"], r, job.ratio * 20.0, SETTLING_BAND)
    return {**asdict(job), "settling_time": math.nan if settle is None else settle}


def gain_jobs(c1s, c2s, ratios, starts: int, duration: float, dt: float) -> list[GainJob]:
    return [GainJob(a, b, q, k, duration, dt) for a, b, q, k in itertools.product(c1s, c2s, ratios, range(starts))]


def gain_stubs(job: GainJob | tuple[GainJob, ...]) -> list[dict]:
    """The key columns of each run of a job (one pair, or a chunk of them)."""
    return [asdict(j) for j in (job if isinstance(job, tuple) else (job,))]


def gain_subset(job: GainJob | tuple[GainJob, ...], keep: list[int]) -> GainJob | tuple[GainJob, ...]:
    """The job with only the runs `keep` (indices into a chunk)."""
    return tuple(job[i] for i in keep) if isinstance(job, tuple) else job


def gain_key_columns() -> list[str]:
    """What names a run of the gain map: its pair's fields (`start` is its seed)."""
    return [f.name for f in fields(GainJob)]


def gain_columns() -> list[str]:
    return [f.name for f in fields(GainJob)] + ["settling_time"]


def summarise_gains(rows: list[dict]) -> list[dict]:
    """Worst settling time over the starts, per (c1, c2, ratio); nan: some start never settled
    (or ended at the run timeout, counted in `timeouts`)."""
    groups: dict[tuple, list[float]] = {}
    late: dict[tuple, int] = {}
    for r in rows:
        key = (float(r["c1"]), float(r["c2"]), float(r["ratio"]))
        timeout = r.get("status") not in (None, "ok")
        late[key] = late.get(key, 0) + timeout
        groups.setdefault(key, []).append(math.nan if timeout else float(r["settling_time"]))
    return [
        {
            "c1": k[0],
            "c2": k[1],
            "ratio": k[2],
            "starts": len(v),
            "worst_settling_s": max(v) if all(math.isfinite(x) for x in v) else math.nan,
            "timeouts": late[k],
        }
        for k, v in sorted(groups.items())
    ]
