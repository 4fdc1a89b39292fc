"""What the safety filter (world/safety.py) costs per tick (docs/benchmarks.md#safety).

For N = 6, 10, 20 agents, `safe_commands` on states of two kinds, each drawn afresh:

- "spread": a swarm evenly spaced on a circle of 3 N m round a target, each agent headed
  round it at 1 m/s (the laws' commands are safe): the check alone, no QP;
- "crowded": the agents in a 6 m x 6 m arena (a cluster by a wall), random headings and
  commands, radius 0.5 m: the filter at work, its QPs solved (counted).

And the same through the engine: `swarm sim` of a ring scenario with and without a
[safety] table (measuring only / filtering), its wall time per tick. Prints a table;
asserts nothing.

    python benchmarks/bench_safety.py            # N = 6, 10, 20; 400 states each
    python benchmarks/bench_safety.py --sizes 6,10,20,50 --states 1000
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from swarm.contracts.scenario import parse_scenario
from swarm.offline.sim import run_sim
from swarm.world.safety import Arena, Barriers, safe_commands


def spread(rng, n: int):
    a = np.linspace(0, 2 * math.pi, n, endpoint=False) + rng.uniform(0, 2 * math.pi)  # evenly spaced: 18.8 m
    r = 3.0 * n
    x, y = r * np.cos(a), r * np.sin(a)
    g = a + math.pi / 2
    return Barriers(radius=0.5, lookahead=0.125, gamma=2.0), x, y, g, np.ones(n), np.full(n, 1.0 / r)


def crowded(rng, n: int):
    arena = Arena.rectangle(-3.0, -3.0, 3.0, 3.0)
    bar = Barriers(radius=0.5, lookahead=0.125, gamma=2.0, arena=arena)
    xs: list[float] = []
    ys: list[float] = []
    while len(xs) < n:
        p = rng.uniform(-2.4, 2.4, 2)
        if all(math.hypot(p[0] - a, p[1] - b) > 0.9 for a, b in zip(xs, ys)):
            xs.append(p[0])
            ys.append(p[1])
    g = rng.uniform(-math.pi, math.pi, n)
    return bar, np.array(xs), np.array(ys), g, np.ones(n), rng.uniform(-1.0, 1.0, n)


def per_call(make, n: int, states: int, rng) -> tuple[float, float, float]:
    """(median us per call, mean QPs per call, share of calls that changed something)."""
    times, solves, changed = [], 0, 0
    for _ in range(states):
        bar, x, y, g, v, u = make(rng, n)
        present = np.ones(n, dtype=bool)
        u_max = np.full(n, 2.0)
        t0 = time.perf_counter()
        f = safe_commands(bar, x, y, g, v, u, u_max, present)
        times.append(time.perf_counter() - t0)
        solves += f.solves
        changed += bool(f.changed.any())
    return float(np.median(times) * 1e6), solves / states, changed / states


def ring(n: int, safety: dict | None) -> dict:
    """A ring of n leaders on one orbit (r = 3 n m), the safety table added."""
    r = 3.0 * n
    agents = [
        {
            "id": k + 1,
            "role": "leader",
            "x": r * math.cos(2 * math.pi * k / n),
            "y": r * math.sin(2 * math.pi * k / n),
            "heading": 2 * math.pi * k / n + math.pi / 2,
            "speed": 1.0 + 0.05 * k,  # some faster than others: they catch up
            "orbit_radius": r,
            "max_turn_rate": 2.0,
        }
        for k in range(n)
    ]
    d: dict = {"name": f"ring{n}", "run": {"dt": 0.01, "duration": 20.0}, "gains": {"c1": 1.0, "c2": 0.5}}
    d["agents"] = agents
    if safety is not None:
        d["safety"] = safety
    return d


def sim_ms_per_tick(n: int, safety: dict | None) -> tuple[float, dict]:
    s = parse_scenario(ring(n, safety))
    t0 = time.perf_counter()
    res = run_sim(s)
    wall = time.perf_counter() - t0
    return wall / s.run.ticks * 1e3, res.summary().get("safety") or {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="6,10,20")
    ap.add_argument("--states", type=int, default=400)
    args = ap.parse_args()
    sizes = [int(v) for v in args.sizes.split(",")]
    rng = np.random.default_rng(34)
    print("safe_commands per call (median over states):")
    print(f"{'N':>4} {'spread us':>10} {'crowded us':>11} {'QPs/call':>9} {'changed':>8}")
    for n in sizes:
        sp, _, _ = per_call(spread, n, args.states, rng)
        cr, qps, ch = per_call(crowded, n, args.states, rng)
        print(f"{n:>4} {sp:>10.0f} {cr:>11.0f} {qps:>9.2f} {ch:>8.0%}")
    print("\nswarm sim of a ring of leaders (20 s, dt 0.01), ms per tick:")
    print(f"{'N':>4} {'no table':>9} {'measure':>8} {'filter':>8} {'interventions':>14} {'min dist m':>11}")
    for n in sizes:
        bare, _ = sim_ms_per_tick(n, None)
        measured, _ = sim_ms_per_tick(n, {"radius": 0.5, "enabled": False})
        filt, figs = sim_ms_per_tick(n, {"radius": 0.5})
        print(
            f"{n:>4} {bare:>9.3f} {measured:>8.3f} {filt:>8.3f} {figs['interventions']:>14} "
            f"{figs['min_distance']:>11.3f}"
        )


if __name__ == "__main__":
    main()
