"""Agent-steps per second of `SwarmEnv` and `VectorSwarmEnv` (docs/guides/learning.md#throughput).

    .venv/bin/python -m swarm.env.throughput            # B = 1, 16, 256, 4096, 3 rounds
    .venv/bin/python -m swarm.env.throughput 1 16 --rounds 1 --selection nearest

The job: a random 10-agent swarm of `swarm study swarms` (`scenario` below: 2 leaders,
sticky selection unless told, unlimited sensing), every
agent controlled (agents="all"), actions from the paper's bearing law written as a policy
on the observation arrays (vectorised for the vector env, one array at a time for
SwarmEnv). A measurement times `steps` steps after 20 warm-up steps of a fresh episode
(resets not timed); the configurations are interleaved round by round and the median of
the rounds is reported. SwarmEnv steps one swarm: B of them one after the other run at
the same agent-steps per second, so it is measured at B = 1.
"""

from __future__ import annotations

import argparse
import functools
import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm.env.observation import index

OUT, HEADING, BEARING = index("out.present"), index("out.heading"), index("out.bearing")
TARGET, T_BEARING, T_RANGE, RADIUS = (
    index("target.present"),
    index("target.bearing"),
    index("target.range"),
    index("target.orbit_radius"),
)
WARMUP = 20


def policy(a: np.ndarray) -> Any:
    """Followers: the bearing law on the out-neighbour (0.5 rad/s with none); leaders: steer
    to put the target abeam at the orbit radius (a crude orbit hold). On the last axis."""
    follow = np.where(a[..., OUT] == 0.0, 0.5, 1.0 * a[..., HEADING] + 0.5 * np.sin(a[..., BEARING]))
    err = a[..., T_RANGE] - a[..., RADIUS]
    lead = 2.0 * (a[..., T_BEARING] - (math.pi / 2 - np.clip(0.5 * err / np.maximum(a[..., RADIUS], 1e-9), -1, 1)))
    return np.where(a[..., TARGET] == 1.0, lead, follow)


policy.vectorised = True  # type: ignore[attr-defined]


def scenario(selection: str = "sticky", seed: int = 0) -> Any:
    """`swarm study swarms`' random swarm `seed` of 10 agents (swarm.env.vector.random_scenario)."""
    # lazy: the scenario's model (pydantic) only when it runs
    from swarm.env.vector import random_scenario

    return random_scenario(10, seed, selection)


def measure_vector(s: Any, b: int, steps: int) -> float:
    # lazy: the batch engine only when it runs
    from swarm.env.vector import VectorSwarmEnv

    env = VectorSwarmEnv(s, b, seed=0, agents="all")
    obs, _ = env.reset()
    for _ in range(WARMUP):
        obs, *_ = env.step(policy(obs))
    t0 = time.perf_counter()
    for _ in range(steps):
        obs, *_ = env.step(policy(obs))
    return b * env.n_agents * steps / (time.perf_counter() - t0)


def measure_swarm_env(s: Any, steps: int) -> float:
    # lazy: pettingzoo (the `env` extra) only when it runs
    from swarm.env.parallel import SwarmEnv

    env = SwarmEnv(s, agents="all")
    obs, _ = env.reset(seed=0)

    def act(o: dict) -> dict:
        return {n: float(policy(a)) for n, a in o.items()}

    for _ in range(WARMUP):
        obs, *_ = env.step(act(obs))
    t0 = time.perf_counter()
    n = 0
    for _ in range(steps):
        n += len(obs)
        obs, *_ = env.step(act(obs))
    return n / (time.perf_counter() - t0)


def steps_for(b: int) -> int:
    return max(10, min(1000, 40_000 // (10 * b)))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sizes", nargs="*", type=int, default=[1, 16, 256, 4096])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--selection", default="sticky")
    args = p.parse_args(argv)
    s = scenario(args.selection)
    runs: dict[str, list[float]] = {}
    jobs: list[tuple[str, Callable[[], float]]] = [("SwarmEnv B=1", functools.partial(measure_swarm_env, s, 1000))]
    jobs += [(f"VectorSwarmEnv B={b}", functools.partial(measure_vector, s, b, steps_for(b))) for b in args.sizes]
    for r in range(args.rounds):
        for name, job in jobs:
            v = job()
            runs.setdefault(name, []).append(v)
            print(f"round {r + 1} {name}: {v:,.0f} agent-steps/s", flush=True)
    print("| environment | agent-steps/s (median) | rounds |\n| --- | --- | --- |")
    for name, vs in runs.items():
        print(f"| {name} | {statistics.median(vs):,.0f} | {', '.join(f'{v:,.0f}' for v in vs)} |")


if __name__ == "__main__":
    main()
