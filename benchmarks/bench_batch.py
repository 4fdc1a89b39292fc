"""The batch engine (swarm/offline/batch.py) against `swarm sim`'s per-agent engine (swarm/offline/sim.py):
agent-ticks per second of each, their ratio, and how far apart their trajectories are.

    .venv/bin/python benchmarks/bench_batch.py            # case2, a 30-agent swarm, a 200-seed study
    .venv/bin/python benchmarks/bench_batch.py --quick    # shorter runs, fewer seeds
    .venv/bin/python benchmarks/bench_batch.py --seeds 200 --baseline-seeds 10

1. One run of scenarios/case2.toml (6 agents, 15,000 ticks), each engine in memory.
2. One random 30-agent swarm (3 leaders, unlimited sensing, 500 s at dt 0.05).
3. A 200-seed study of 10-agent swarms (`swarm study swarms --seeds 200`'s default
   setting: 2 leaders, 500 s at dt 0.05), in one process, counting all a study worker
   does per run (drawing the swarm, the cut-off check, the run, the CSV row): the batch
   engine on every seed, in the chunks `swarm study swarms --seeds 200 -j 1` makes; the
   per-agent engine on the first --baseline-seeds seeds only (each takes seconds), its
   rate scaled to 200 seeds. Equality: the batch engine's trajectories of those seeds
   against the per-agent ones (max |dx|, |dy| over every tick and agent), and their rows.

Figures only: nothing is asserted. The machine is shared: the load average is printed
before and after, and the two engines run one after the other, so compare the ratio.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.offline.batch import run_batch  # noqa: E402
from swarm.offline.sim import run_sim  # noqa: E402
from swarm.study.batch import run_swarm_chunk, swarm_chunks  # noqa: E402
from swarm.study.swarms import SwarmSetting, cut_off_at_start, random_swarm, swarm_row  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def deviation(a, b) -> float:
    a, b = a.recorder.arrays(), b.recorder.arrays()
    return max(float(np.max(np.abs(a[k] - b[k]))) for k in ("x", "y"))


def identical(a, b) -> bool:
    a, b = a.recorder.arrays(), b.recorder.arrays()
    return all(np.array_equal(a[k], b[k], equal_nan=True) for k in ("x", "y", "heading", "u", "out"))


def timed(f, *args, **kw):
    t0 = time.perf_counter()
    out = f(*args, **kw)
    return out, time.perf_counter() - t0


def one_run(label: str, s, duration: float | None) -> None:
    ticks = int(round((duration or s.run.duration) / s.run.dt))
    agent_ticks = ticks * len(s.agents)
    ref, t_ref = timed(run_sim, s, duration)
    (got,), t_got = timed(run_batch, [s], duration)
    print(f"\n{label}: {len(s.agents)} agents x {ticks} ticks")
    print(f"  per-agent (run_sim)  {agent_ticks / t_ref:>12,.0f} agent-ticks/s  ({t_ref:.2f} s)")
    print(f"  batch (run_batch)    {agent_ticks / t_got:>12,.0f} agent-ticks/s  ({t_got:.2f} s)")
    print(f"  ratio                {t_ref / t_got:>12.2f} x")
    print(
        f"  max deviation        {deviation(ref, got):>12.3g} m   (bit-identical x, y, heading, u, out: "
        f"{identical(ref, got)}; events equal: {got.events == ref.events}, {len(ref.events)} of them)"
    )


def study(seeds: int, baseline: int, setting: SwarmSetting) -> None:
    ticks = int(round(setting.duration / setting.dt))
    per_run = ticks * setting.n
    print(
        f"\nstudy: {seeds} random swarms, {setting.label()}, {setting.duration:g} s at dt {setting.dt:g} s "
        f"({per_run:,} agent-ticks each), one process"
    )
    chunks = swarm_chunks([setting], range(seeds), workers=1)
    t0 = time.perf_counter()
    rows = {}
    for job in chunks:
        for r in run_swarm_chunk(job):
            rows[r["seed"]] = r
    t_batch = time.perf_counter() - t0
    print(
        f"  batch      {seeds} runs in {len(chunks)} chunks of {len(chunks[0][1])}: {t_batch:.1f} s, "
        f"{seeds * per_run / t_batch:>12,.0f} agent-ticks/s"
    )
    refs, t_base, base_rows = [], 0.0, {}
    for sd in range(baseline):
        t0 = time.perf_counter()
        s = random_swarm(setting, sd)
        cut = cut_off_at_start(s)
        res = run_sim(s)
        base_rows[sd] = swarm_row(setting, sd, cut, res, 0.0)
        t_base += time.perf_counter() - t0
        refs.append((s, res))
    rate = baseline * per_run / t_base
    print(
        f"  per-agent  {baseline} runs (seeds 0..{baseline - 1}): {t_base:.1f} s, {rate:>12,.0f} agent-ticks/s "
        f"(200 seeds at this rate: {seeds * per_run / rate / 60:.1f} min)"
    )
    print(f"  ratio      {seeds * per_run / t_batch / rate:.1f} x")
    again = run_batch([s for s, _ in refs], lean=True)
    devs = [deviation(r, g) for (_, r), g in zip(refs, again)]
    same_rows = all({**rows[sd], "wall_s": 0} == {**base_rows[sd], "wall_s": 0} for sd in range(baseline))
    print(
        f"  equality   max deviation over seeds 0..{baseline - 1}: {max(devs):.3g} m; "
        f"rows equal (wall_s apart): {same_rows}"
    )
    conv = sum(1 for r in rows.values() if r["converged"])
    print(f"  outcome    converged {conv} / {seeds}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="100 s runs, 40 seeds, 3 baseline seeds")
    ap.add_argument("--seeds", type=int, default=None, help="study seeds (default 200)")
    ap.add_argument("--baseline-seeds", type=int, default=None, help="per-agent runs in the study (default 10)")
    a = ap.parse_args()
    seeds = a.seeds or (40 if a.quick else 200)
    baseline = a.baseline_seeds or (3 if a.quick else 10)
    duration = 100.0 if a.quick else 500.0
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    case2 = load_scenario(ROOT / "scenarios" / "case2.toml")
    one_run("case2", case2, 30.0 if a.quick else None)
    one_run("random 30-agent swarm (seed 0)", random_swarm(SwarmSetting(n=30, leaders=3, duration=duration), 0), None)
    study(seeds, baseline, SwarmSetting(duration=duration))
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
