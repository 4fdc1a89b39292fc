"""A stalled world on real-time robots (issue 34, item 3; docs/guides/safety-on-robots.md#world-stops),
seen at the robots' side: `swarm up --robots` of six robots against a simulated fleet in this
process (benchmarks/robots_stops.py's `Bench`: each command's arrival recorded at its robot);
once every robot moves, the world is stopped with SIGSTOP for `--stall` s, then continued.

Per run it prints, over every robot: the commands that reached the robots in the 1 s after
SIGCONT, the least gap before a motion command to one robot from the stall to 3 s after it
(half a tick is the bound: 25 ms at the scenario's dt = 0.05 s; a zero twist right behind
another command is a stop, not a burst: the least gap of all is printed apart), whether each robot's first
command after the stall was a zero twist, and the run's `late` events, `late_ticks` and
`skipped_ticks` from its summary.json. Before the re-anchoring clock (the issue, 2026-11-28):
17 twists per robot within 0.25 s of SIGCONT, 16 of them less than 5 ms apart, no event.

    .venv/bin/python benchmarks/robots_stall.py              # 3 runs, 3 s stalls
    .venv/bin/python benchmarks/robots_stall.py --runs 5 --stall 1
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from robots_stops import N_ROBOTS, Bench, world_of  # noqa: E402


def one_run(b: Bench, stall: float) -> dict:
    p = b.up()
    world = world_of(p)
    t_stop = time.monotonic()
    os.kill(world, signal.SIGSTOP)
    time.sleep(stall)
    t_cont = time.monotonic()
    os.kill(world, signal.SIGCONT)
    time.sleep(3.0)
    b.finish(p)
    after = [a for a in b.fleet.since(t_stop) if a[0] <= t_cont + 3.0]
    per_robot: dict[int, list[tuple[float, float, float]]] = {}
    for when, aid, vx, wz in after:
        per_robot.setdefault(aid, []).append((when, vx, wz))
    # a burst is motion commands close together; a zero twist right behind another command (the
    # world's hold behind a motion command that zenoh flushed only when the world was continued,
    # a zero repeated by the world's watchdog) stops the robot: the gaps counted end in a
    # motion command
    gaps = [
        b2[0] - b1[0] for cmds in per_robot.values() for b1, b2 in zip(cmds, cmds[1:]) if (b2[1], b2[2]) != (0.0, 0.0)
    ]
    zero_gaps = [b2[0] - b1[0] for cmds in per_robot.values() for b1, b2 in zip(cmds, cmds[1:])]
    # (commands in flight when the world stopped arrive after t_stop: the first one sent after
    # the stall is the first to arrive after SIGCONT)
    resumed = {aid: [c for c in cmds if c[0] > t_cont] for aid, cmds in per_robot.items()}
    first_zero = sum(1 for cmds in resumed.values() if cmds and (cmds[0][1], cmds[0][2]) == (0.0, 0.0))
    within_1s = sum(1 for when, *_ in after if t_cont <= when <= t_cont + 1.0)
    summary = json.loads((b.work / f"run{b.k}" / "summary.json").read_text())
    late = [e for e in summary.get("events", []) if e["kind"] == "late"]
    return {
        "commands_1s_after": within_1s,
        "per_robot_1s": within_1s / N_ROBOTS,
        "min_gap_ms": 1e3 * min(gaps) if gaps else None,
        "min_gap_any_ms": 1e3 * min(zero_gaps) if zero_gaps else None,
        "first_is_zero": f"{first_zero}/{len(per_robot)}",
        "late_events": len(late),
        "late_skipped": late[0]["skipped"] if late else None,
        "late_ticks": summary.get("late_ticks"),
        "skipped_ticks": summary.get("skipped_ticks"),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--stall", type=float, default=3.0, help="s the world is stopped")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="stall") as d:
        b = Bench(Path(d))
        try:
            rows = []
            for k in range(args.runs):
                rows.append(one_run(b, args.stall))
                print(f"run {k + 1}: {rows[-1]}", flush=True)
        finally:
            b.close()
    print(f"\nworld SIGSTOP {args.stall:g} s, {N_ROBOTS} robots, dt 0.05 s (half a tick: 25 ms)")
    print("run | commands/robot, 1 s after | least gap, ms (any) | first after stall zero | late events | late/skipped")
    for k, r in enumerate(rows, 1):
        gap = f"{r['min_gap_ms']:.1f} ({r['min_gap_any_ms']:.1f})" if r["min_gap_ms"] is not None else "-"
        print(
            f"{k} | {r['per_robot_1s']:.1f} | {gap} | {r['first_is_zero']} | {r['late_events']} "
            f"(skipped {r['late_skipped']}) | {r['late_ticks']}/{r['skipped_ticks']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
