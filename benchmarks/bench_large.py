"""A large swarm on this machine, as agent processes (a benchmark, not a test).

    python benchmarks/bench_large.py [--n 200] [--leaders 20] [--duration 130] [--dt 0.05]
                                     [--neighbours K] [--json FILE] [--keep]

Starts `swarm up` (lockstep, sticky selection, unlimited sensing unless --neighbours) on
the ring scenario of bench_runtime.py with N agents and `--leaders` leaders evenly spaced
(shallow trees converge sooner: 200 agents under 20 leaders are within 1% of their
expected radii after 130 s), and prints:

- the time from Popen of `swarm up` to the first tick, and the world's own startup_s;
- lockstep ticks/s over the run, converged or not (summary.json), the worst relative error;
- RSS of every agent process while ticking (followers and leaders apart) and of the world;
- the largest difference of the trajectory from the batch engine's (swarm/offline/batch.py) on the
  same scenario: lockstep `swarm up` equals `swarm sim`, so it should be 0;
- what is left after `swarm up` exits: processes of its group (should be none).

Every process is started here; at the end it SIGTERMs what it started and SIGKILLs whatever
is left of it. Nothing else is signalled. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import os

import numpy as np
from bench_runtime import PY, MemSampler, Tracked, is_agent, is_world, log, scenario_toml, world_started  # noqa: E402

from swarm.contracts.scenario import parse_scenario  # noqa: E402
from swarm.contracts.vocabulary import EventKind, ExitCode  # noqa: E402
from swarm.offline.batch import run_batch  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="agents (default 200)")
    ap.add_argument("--leaders", type=int, default=20, help="leaders among them, evenly spaced (default 20)")
    ap.add_argument("--duration", type=float, default=130.0, help="simulated s (default 130)")
    ap.add_argument("--dt", type=float, default=0.05, help="s per tick (default 0.05)")
    ap.add_argument("--neighbours", type=int, default=None, help="a sensing range with about this many sensed")
    ap.add_argument("--json", type=Path, help="write the figures to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the work directory")
    a = ap.parse_args(argv)

    rt = tempfile.mkdtemp(prefix="sw", dir="/tmp")
    work = Path(tempfile.mkdtemp(prefix="swarm-large-"))
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt, "PYTHONUNBUFFERED": "1"}
    text = scenario_toml(a.n, a.neighbours, leaders=a.leaders, selection="sticky", dt=a.dt, duration=a.duration)
    toml = work / f"large{a.n}.toml"
    toml.write_text(text)
    out = work / "out"
    tr, mem, wmem = Tracked(), MemSampler(), MemSampler()
    st: dict = {"started": None, "agents": [], "world": None, "seen": set(), "last": 0.0}
    res: dict = {"n": a.n, "leaders": a.leaders, "dt": a.dt, "duration": a.duration, "neighbours": a.neighbours}
    try:
        log(f"swarm up: {a.n} agents ({a.leaders} leaders), {a.duration:g} s at dt {a.dt:g}; work dir {work}")
        t_popen = time.time()
        up = tr.spawn([PY, "-m", "swarm", "up", str(toml), "--out", str(out), "--no-plots"], work / "up.log", env)

        def sample():
            now = time.monotonic()
            if now - st["last"] > 1.0:
                st["last"] = now
                kids = tr.discover(up)
                st["seen"].update(k.pid for k in kids)
                st["agents"] = [k for k in kids if is_agent(k)]
                ws = [k for k in kids if is_world(k)]
                st["world"] = ws[0] if ws else st["world"]
            if st["started"] is None and world_started(out):
                st["started"] = now
                log("  ticking")
            if st["started"] is not None and now - st["started"] > 2.0:
                mem.sample_rss(st["agents"])
                wmem.sample_rss([st["world"]] if st["world"] else [])

        wait_until(lambda: up.poll() is not None or bool(sample()), 1800, 0.5)
        res["exit_code"] = up.poll()
        time.sleep(1.0)
        left = []
        for pid in st["seen"]:
            try:
                p = psutil.Process(pid)
                if p.status() != psutil.STATUS_ZOMBIE:
                    left.append(pid)
            except psutil.NoSuchProcess:
                pass
        res["left_after_exit"] = left
        res["processes_seen"] = len(st["seen"])
    finally:
        tr.stop()
    summary = json.loads((out / "summary.json").read_text())
    start = next((e for e in summary.get("events", []) if e.get("kind") == EventKind.START), {})
    agents = summary["agents"]
    rel = [v["relative_error"] for v in agents.values()]
    res.update(
        first_tick_s=start.get("wall_time", t_popen) - t_popen,
        startup_s=start.get("startup_s"),
        ticks=summary.get("ticks"),
        ticks_per_second=summary.get("ticks_per_second"),
        converged=summary.get("converged"),
        worst_relative_error=max((r for r in rel if r is not None), default=None),
        without_leader=sum(r is None for r in rel),
    )
    roles = {int(k): v["role"] for k, v in agents.items()}
    by_role: dict[str, list[float]] = {"leader": [], "follower": []}
    for pid, rss in mem.rss.items():
        aid = next((int(k) for k, v in agents.items() if v.get("pid") == pid), None)
        if aid is not None:
            by_role[roles[aid]].append(rss)
    res["rss_mb"] = {
        role: {"n": len(v), "mean": float(np.mean(v)) if v else None, "max": max(v) if v else None}
        for role, v in by_role.items()
    }
    res["world_rss_mb"] = max(wmem.rss.values(), default=None)
    s = parse_scenario(tomllib.loads(text))
    ref = run_batch([s], a.duration)[0].recorder.arrays()
    with np.load(out / "trajectory.npz") as z:
        res["max_diff_to_batch_m"] = float(max(np.max(np.abs(z["x"] - ref["x"])), np.max(np.abs(z["y"] - ref["y"]))))
    if a.json:
        a.json.write_text(json.dumps(res, indent=2) + "\n")
    if not a.keep and res["exit_code"] == ExitCode.OK:
        shutil.rmtree(work, ignore_errors=True)
    shutil.rmtree(rt, ignore_errors=True)
    if res["exit_code"] != ExitCode.OK or res["startup_s"] is None:
        print(f"swarm up exited {res['exit_code']}; see {work}")
        print(json.dumps(res, indent=2))
        return ExitCode.FAILED
    r = res["rss_mb"]
    print(
        f"{a.n} agent processes ({a.leaders} leaders), {a.duration:g} s simulated at dt {a.dt:g}, "
        f"sensing {'unlimited' if a.neighbours is None else f'about {a.neighbours} others'}:"
    )
    print(
        f"  first tick {res['first_tick_s']:.1f} s after Popen of swarm up (world startup_s {res['startup_s']:.1f} s)"
    )
    print(
        f"  {res['ticks']} ticks at {res['ticks_per_second']:.1f} ticks/s; converged {res['converged']} "
        f"(worst relative radial error {res['worst_relative_error']:.4f}, {res['without_leader']} without a leader)"
    )
    mb = lambda v: "n/a" if v is None else f"{v:.1f}"  # noqa: E731  (a run too short to be sampled has none)
    print(
        f"  RSS while ticking, MB: followers mean {mb(r['follower']['mean'])} max {mb(r['follower']['max'])} "
        f"(n={r['follower']['n']}); leaders mean {mb(r['leader']['mean'])} max {mb(r['leader']['max'])} "
        f"(n={r['leader']['n']}); world {mb(res['world_rss_mb'])}"
    )
    print(f"  trajectory vs the batch engine: largest difference {res['max_diff_to_batch_m']:.3g} m")
    print(
        f"  swarm up exit code {res['exit_code']}; processes of its run left afterwards: {len(res['left_after_exit'])} "
        f"(of {res['processes_seen']} seen)"
    )
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
