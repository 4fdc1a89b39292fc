"""Where the lockstep tick's time goes: `swarm up` with parts of its work taken out, against
the bare-zenoh floor, in one run (a benchmark, not a test).

    python benchmarks/bench_ablation.py [--sizes 6,20,50] [--neighbours 8] [--repeat 2]
                                        [--swarm-seconds 3] [--quiet-wait 20] [--json FILE]

For each N, interleaved and repeated (the table shows the best run of each):

- floor:  benchmarks/bare_hub.py + N bare_client.py (bench_runtime.py's baseline);
- swarm:  `swarm up` of bench_runtime.py's ring scenario, as shipped;
- recording: the same with a world that writes no recording (benchmarks/ablation/
          sitecustomize.py);
- world:  the same with a world that re-sends its first frames and neither senses,
          encodes, records nor integrates;
- agents: the same with agents that decide nothing (read the tick, send a fixed command);
- both:   world and agents as above.

A column's ratio to the floor is what the runtime would reach if that work cost nothing:
"both" is the price of the runtime's shells alone (processes, keys, claims, checks,
the world's inbox), the rest is the agents' and the world's Python per tick. Only processes
started here are signalled (bench_runtime.py's Tracked).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_runtime import base_ticks, best, fmt, log, run_baseline, run_swarm, wait_quiet  # noqa: E402

from swarm.contracts.vocabulary import ExitCode  # noqa: E402

ABLATION = Path(__file__).resolve().parent / "ablation"
MODES = ("swarm", "recording", "world", "agents", "both")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="6,20,50", help="agent counts, comma-separated (default 6,20,50)")
    ap.add_argument(
        "--neighbours",
        type=int,
        default=8,
        help="a sensing range under which each agent senses about this many others at the start "
        "(default 8; 0: unlimited sensing)",
    )
    ap.add_argument("--repeat", type=int, default=2, help="runs of each kind per N (default 2)")
    ap.add_argument("--swarm-seconds", type=float, default=3.0, help="aim for this many s of ticking per run")
    ap.add_argument(
        "--quiet-wait",
        type=float,
        default=20.0,
        help="before each run wait up to this many s for the machine to be quiet",
    )
    ap.add_argument("--json", type=Path, help="write all results to this JSON file")
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.sizes.split(",") if x.strip()]
    neighbours = a.neighbours or None

    rt = tempfile.mkdtemp(prefix="sw", dir="/tmp")  # short: Unix socket paths are limited to 108 bytes
    work = Path(tempfile.mkdtemp(prefix="swarm-ablation-"))
    base_env = {**os.environ, "SWARM_RUNTIME_DIR": rt, "PYTHONUNBUFFERED": "1", "BENCH_CLIENT_HANDLER": "direct"}
    base_env.pop("SWARM_ABLATE", None)
    path = os.pathsep.join(p for p in (str(ABLATION), base_env.get("PYTHONPATH", "")) if p)
    results: dict = {"sizes": sizes, "neighbours": neighbours, "repeat": a.repeat, "by_n": {}}
    try:
        for n in sizes:
            ticks, warmup = base_ticks(n, quick=True)
            r = results["by_n"][str(n)] = {"floor": [], **{m: [] for m in MODES}}
            for k in range(a.repeat):
                wait_quiet(0.5, a.quiet_wait)
                b = run_baseline(n, ticks, warmup, work, base_env, f"{n}-{k}")
                r["floor"].append(b)
                log(f"[N={n} run {k + 1}] floor {fmt(b.get('ticks_per_second'))} ticks/s {b.get('error', '')}")
                tps = b.get("ticks_per_second") or 20000 / n
                sticks = int(min(40000, max(300, tps * a.swarm_seconds)))
                for m in MODES:
                    env = dict(base_env) if m == "swarm" else {**base_env, "PYTHONPATH": path, "SWARM_ABLATE": m}
                    wait_quiet(0.5, a.quiet_wait)
                    s = run_swarm(n, sticks, work, env, f"{n}-{k}-{m}", neighbours=neighbours)
                    r[m].append(s)
                    log(f"[N={n} run {k + 1}] {m}: {fmt(s.get('ticks_per_second'))} ticks/s {s.get('error', '')}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(rt, ignore_errors=True)
    print(report(results))
    if a.json:
        a.json.write_text(json.dumps(results, indent=2) + "\n")
    return ExitCode.OK


def report(results: dict) -> str:
    sensing = (
        "unlimited sensing"
        if results["neighbours"] is None
        else f"a range under which each agent senses about {results['neighbours']} others at the start"
    )
    lines = [
        f"lockstep ticks/s (best of {results['repeat']}), {sensing}; in brackets: against the floor",
        "  N |  floor |          swarm |   no recording | world does nothing | agents decide nothing |           both",
        "-" * 115,
    ]
    for n in results["sizes"]:
        r = results["by_n"][str(n)]
        floor = (best(r["floor"]) or {}).get("ticks_per_second")
        cells = []
        for m in MODES:
            tps = (best(r[m]) or {}).get("ticks_per_second")
            ratio = f"({tps / floor:.2f})" if tps and floor else "(-)"
            cells.append(f"{fmt(tps):>6} {ratio:>6}")
        lines.append(
            f"{n:>3} | {fmt(floor):>6} | {cells[0]:>14} | {cells[1]:>14} | {cells[2]:>18} | "
            f"{cells[3]:>21} | {cells[4]:>14}"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
