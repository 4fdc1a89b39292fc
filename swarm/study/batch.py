"""`swarm study` on the batch engine (swarm/offline/batch.py): many runs per job.

A job is a chunk of runs that share a batch (one setting's seeds; gain-map pairs of one
duration and dt); a worker runs the chunk as one batch and returns its rows, the rows
`run_swarm` / `run_gain` would return run by run (the same RunResults: the batch
engine equals the per-agent one), except `wall_s`, which is the chunk's wall time
shared out over its runs. Chunks are small enough that every worker gets several
(rows stream to runs.csv as chunks finish, and Ctrl-C loses at most the chunks under
way) and that a chunk's recording stays within MEMORY_BUDGET bytes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

from swarm.offline.batch import run_batch
from swarm.study.gains import GainJob, gain_row, pair_scenario
from swarm.study.swarms import SwarmSetting, cut_off_at_start, random_swarm, swarm_row

MAX_MEMBERS = 64  # runs per batch, at most: beyond this the per-tick overhead is already paid
CHUNKS_PER_WORKER = 4  # at least this many chunks per worker when there are enough runs
MEMORY_BUDGET = 128 << 20  # bytes of recorded x, y, out per chunk (24 bytes per agent-tick)


def chunk_size(runs: int, workers: int, agents: int, ticks: int) -> int:
    """Runs per chunk for `runs` runs of `agents` x `ticks` on `workers` processes."""
    by_memory = MEMORY_BUDGET // (24 * agents * (ticks + 1))
    by_spread = math.ceil(runs / (CHUNKS_PER_WORKER * max(1, workers)))
    return max(1, min(MAX_MEMBERS, by_memory, by_spread))


def swarm_chunks(
    settings: Sequence[SwarmSetting], seeds: Sequence[int], workers: int
) -> list[tuple[SwarmSetting, tuple[int, ...]]]:
    """(setting, seeds) jobs: each setting's seeds cut into chunks."""
    seeds = list(seeds)
    jobs = []
    for st in settings:
        size = chunk_size(len(seeds), workers, st.n, int(round(st.duration / st.dt)))
        jobs += [(st, tuple(seeds[k : k + size])) for k in range(0, len(seeds), size)]
    return jobs


def run_swarm_chunk(job: tuple[SwarmSetting, tuple[int, ...]]) -> list[dict]:
    """Worker: a chunk of one setting's random swarms as one batch; their rows."""
    setting, seeds = job
    t0 = time.perf_counter()
    scenarios = [random_swarm(setting, sd) for sd in seeds]
    cut = [cut_off_at_start(s) for s in scenarios]
    results = run_batch(scenarios, lean=True)
    wall = (time.perf_counter() - t0) / len(seeds)
    return [swarm_row(setting, sd, c, r, wall) for sd, c, r in zip(seeds, cut, results)]


def gain_chunks(jobs: Sequence[GainJob], workers: int) -> list[tuple[GainJob, ...]]:
    """The gain map's runs in chunks of one (duration, dt)."""
    groups: dict[tuple, list[GainJob]] = {}
    for j in jobs:
        groups.setdefault((j.duration, j.dt), []).append(j)
    out = []
    for (duration, dt), js in groups.items():
        size = chunk_size(len(js), workers, 2, int(round(duration / dt)))
        out += [tuple(js[k : k + size]) for k in range(0, len(js), size)]
    return out


def run_gain_chunk(jobs: tuple[GainJob, ...]) -> list[dict]:
    """Worker: a chunk of gain-map pairs as one batch; their rows."""
    results = run_batch([pair_scenario(j) for j in jobs], lean=True)
    return [gain_row(j, r) for j, r in zip(jobs, results)]
