"""The lab-scale rehearsal (issue 34, item 6): scenarios/lab6.toml and lab10.toml, six and ten
TurtleBot3 Burgers in a 4 x 4 m arena, driven by `swarm up --robots` against the simulated
fleet (`swarm robots sim`, 30 ms latency, 0.01 m pose noise, commands truncated to 0.01 as a
TurtleBot3's firmware does), each with the safety filter on and off.

For every run: a copy of the robots file on a free local port (filter off: its [safety] table
with `enabled = false`, which keeps every figure and filters nothing), the fleet started, then
`swarm up` for the scenario's duration on the realtime clock, `--time-scale` times faster than
the wall (the fleet runs its clock as fast: its latency and command timeout are in the run's
seconds; default 1: on a loaded machine a faster run stalls, docs/benchmarks.md#rehearsal),
both in their own process groups, ended (SIGINT, then SIGKILL to the group) however the
script ends. Then summary.json and trajectory.npz are read.

    python benchmarks/rehearsal.py                      # the four runs, realtime: about 16 min
    python benchmarks/rehearsal.py --time-scale 3       # a quick look: about 6 min
    python benchmarks/rehearsal.py --only lab6 --filter on --duration 60

Prints one row per run: the least distance between two robots, collisions, boundary exits
(summary.json's `safety`), whether the run converged and when it settled, and the filter's
interventions per robot. Two readings of convergence: the world's (`converged`: every agent's
last measured radius within 1% of its expected radius; settling: into the 2% band for good),
on the poses the world received, which carry the fleet's noise (0.01 m: 2% of a 0.5 m circle);
and the same tests on each radius averaged over the last --smooth s ("smoothed"). Exit 0 when
every filtered run has no collision and no boundary exit, every robot's fleet report shows
commands, and every filtered run converged (smoothed), 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402
from swarm.world.metrics import CONVERGED_TOL, SETTLING_BAND, settling_time  # noqa: E402

SCENARIOS = {"lab6": ROOT / "scenarios" / "lab6.toml", "lab10": ROOT / "scenarios" / "lab10.toml"}
ROBOTS = {"lab6": ROOT / "scenarios" / "robots" / "lab6.toml", "lab10": ROOT / "scenarios" / "robots" / "lab10.toml"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def robots_copy(robots: Path, endpoint: str, filtering: bool, out: Path) -> Path:
    """A copy of the robots file on `endpoint`; without filtering, `enabled = false` in [safety]."""
    text = robots.read_text()
    text, n = re.subn(r'(?m)^connect\s*=\s*"[^"]*"', f'connect = "{endpoint}"', text)
    if n != 1:
        raise SystemExit(f"{robots}: expected one `connect = ...` line in [ros2]")
    if not filtering:
        text, n = re.subn(r"(?m)^\[safety\]\n", "[safety]\nenabled = false\n", text)
        if n != 1:
            raise SystemExit(f"{robots}: expected one [safety] table")
    out.write_text(text)
    return out


def end_group(p: subprocess.Popen, grace: float = 30.0) -> None:
    """SIGINT to `p`'s process group (its own session), SIGKILL to the group after `grace` s."""
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGINT)
        except ProcessLookupError:
            pass
    try:
        p.wait(grace)
    except subprocess.TimeoutExpired:
        pass
    try:
        os.killpg(p.pid, signal.SIGKILL)  # anything of the group still there (none normally)
    except ProcessLookupError:
        pass
    p.wait()


def smoothed(t: np.ndarray, r: np.ndarray, window: float) -> np.ndarray:
    """Each radius averaged over the `window` s up to it (a trailing mean)."""
    dt = float(t[1] - t[0])
    k = max(1, round(window / dt))
    c = np.cumsum(np.concatenate(([0.0], r)))
    out = np.empty_like(r)
    idx = np.arange(len(r))
    lo = np.maximum(idx + 1 - k, 0)
    out[:] = (c[idx + 1] - c[lo]) / (idx + 1 - lo)
    return out


def run_one(name: str, filtering: bool, args, work: Path) -> dict:
    scenario_path = SCENARIOS[name]
    scenario = load_scenario(scenario_path)
    duration = args.duration or scenario.run.duration
    tag = f"{name}-{'on' if filtering else 'off'}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robots = robots_copy(ROBOTS[name], endpoint, filtering, work / f"{tag}.robots.toml")
    out = work / tag
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    swarm_cmd = [sys.executable, "-m", "swarm"]
    fleet_cmd = [
        *swarm_cmd,
        *("robots", "sim", str(scenario_path), "--robots", str(robots)),
        *("--latency", str(args.latency), "--pose-noise", str(args.pose_noise), "--quantize", str(args.quantize)),
        *("--seed", str(args.seed), "--time-scale", str(args.time_scale)),
    ]
    up_cmd = [
        *swarm_cmd,
        *("up", str(scenario_path), "--robots", str(robots), "--duration", str(duration)),
        *("--time-scale", str(args.time_scale), "--out", str(out), "--no-plots", "--force"),
    ]
    fleet_log, up_log = work / f"{tag}.fleet.log", work / f"{tag}.up.log"
    print(f"{tag}: {duration:g} s at time scale {args.time_scale:g}", flush=True)
    with open(fleet_log, "w") as log:
        fleet = subprocess.Popen(fleet_cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    up = None
    t0 = time.monotonic()
    try:
        if not wait_until(lambda: fleet.poll() is not None or "fleet ready" in fleet_log.read_text(), 120, 0.1):
            raise SystemExit(f"{tag}: the fleet did not get ready within 120 s")
        if fleet.poll() is not None:
            raise SystemExit(f"{tag}: the fleet exited ({fleet.returncode}):\n{fleet_log.read_text()}")
        with open(up_log, "w") as log:
            up = subprocess.Popen(up_cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        up.wait(duration / args.time_scale + 600)
    finally:
        if up is not None:
            end_group(up)
        end_group(fleet)
    wall = time.monotonic() - t0
    if up.returncode != 0:
        raise SystemExit(f"{tag}: swarm up exited {up.returncode}:\n{up_log.read_text()[-4000:]}")

    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "trajectory.npz") as z:
        t, x, y, ids = z["t"], z["x"], z["y"], [int(i) for i in z["ids"]]
    target = (scenario.target.x, scenario.target.y)
    smooth_ok, smooth_settle = True, []
    for k, aid in enumerate(ids):
        expected = summary["agents"][str(aid)]["expected_radius"]
        r = smoothed(t, np.hypot(x[:, k] - target[0], y[:, k] - target[1]), args.smooth)
        smooth_ok &= expected is not None and abs(r[-1] - expected) < CONVERGED_TOL * expected
        smooth_settle.append(None if expected is None else settling_time(t, r, expected, SETTLING_BAND))
    world_settle = [a["settling_time"] for a in summary["agents"].values()]
    safety = summary["safety"]
    report = re.compile(r"robot (\d+): (\d+) commands")
    fleet_report = [line for line in fleet_log.read_text().splitlines() if report.match(line)]
    commands = {int(m.group(1)): int(m.group(2)) for m in map(report.match, fleet_report)}
    return {
        "run": tag,
        "robots": len(ids),
        "filter": filtering,
        "duration": duration,
        "time_scale": args.time_scale,
        "wall": wall,
        "min_distance": safety["min_distance"],
        "min_distance_pair": safety["min_distance_pair"],
        "collisions": safety["collisions"],
        "boundary_exits": safety["boundary_exits"],
        "interventions": safety["interventions"],
        "per_robot": {aid: a["safety"]["interventions"] for aid, a in summary["agents"].items()},
        "infeasible": safety["infeasible"],
        "saturations": safety["saturations"],
        "converged": summary["converged"],
        "settled": None if None in world_settle else max(world_settle),
        "smooth_converged": bool(smooth_ok),
        "smooth_settled": None if None in smooth_settle else max(smooth_settle),
        "worst_error": max(a["relative_error"] for a in summary["agents"].values()),
        "late_ticks": summary.get("late_ticks"),
        "pose_age_max": max(a["pose_age_max"] for a in summary.get("robots", {}).get("agents", {}).values()),
        "commands": commands,
        "fleet_report": fleet_report,
    }


def fmt(v, spec: str = ".0f") -> str:
    return "-" if v is None else format(v, spec)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=sorted(SCENARIOS), action="append", help="this scenario only (repeatable)")
    ap.add_argument("--filter", choices=["on", "off"], action="append", help="these runs only (repeatable)")
    ap.add_argument("--duration", type=float, default=None, help="run seconds (default: each scenario's)")
    ap.add_argument("--time-scale", type=float, default=1.0, help="run seconds per wall second (default 1)")
    ap.add_argument("--latency", type=float, default=0.03, help="s from a pose's measurement to its publication")
    ap.add_argument("--pose-noise", type=float, default=0.01, help="m (yaw: / 0.2 m rad); default 0.01")
    ap.add_argument("--quantize", type=float, default=0.01, help="the fleet truncates commands (default 0.01)")
    ap.add_argument("--seed", type=int, default=0, help="the noise's seed")
    ap.add_argument("--smooth", type=float, default=5.0, help="s: the window of the smoothed radii (default 5)")
    ap.add_argument("--out", type=Path, default=None, help="where the runs go (default: a temporary directory)")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args()
    work = args.out or Path(tempfile.mkdtemp(prefix="rehearsal-"))
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.only or sorted(SCENARIOS, key=lambda n: int(n[3:])):
        for filtering in (False, True):
            if args.filter and ("on" if filtering else "off") not in args.filter:
                continue
            rows.append(run_one(name, filtering, args, work))
    print(
        f"\nlatency {args.latency:g} s, pose noise {args.pose_noise:g} m, quantize {args.quantize:g}, "
        f"time scale {args.time_scale:g}; runs in {work}\n"
    )
    print(
        "| run | robots | filter | least distance, m | collisions | boundary exits | converged (world / smoothed) "
        "| settled, s (world / smoothed) | interventions per robot |"
    )
    print("| --- | ---: | --- | ---: | ---: | ---: | --- | ---: | --- |")
    for r in rows:
        per = ", ".join(f"{aid}: {n}" for aid, n in r["per_robot"].items())
        print(
            f"| {r['run']} | {r['robots']} | {'on' if r['filter'] else 'off'} | {r['min_distance']:.3f} "
            f"({r['min_distance_pair'][0]}-{r['min_distance_pair'][1]}) | {r['collisions']} | {r['boundary_exits']} "
            f"| {r['converged']} / {r['smooth_converged']} | {fmt(r['settled'])} / {fmt(r['smooth_settled'])} "
            f"| {r['interventions'] / r['robots']:.0f} ({per}) |"
        )
    print()
    ok = True
    for r in rows:
        print(
            f"{r['run']}: {r['wall']:.0f} s of wall time; worst final radius error {100 * r['worst_error']:.2f}% "
            f"(measured pose); infeasible {r['infeasible']}, saturations {r['saturations']}, late ticks "
            f"{r['late_ticks']}, pose age max {r['pose_age_max']:.3f} s; commands per robot {r['commands']}"
        )
        reached = len(r["commands"]) == r["robots"] and all(n > 0 for n in r["commands"].values())
        ok &= reached
        if r["filter"]:
            ok &= r["collisions"] == 0 and r["boundary_exits"] == 0 and r["smooth_converged"]
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
