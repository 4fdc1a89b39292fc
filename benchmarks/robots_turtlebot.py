"""The paper's hardware experiment through the robot world: scenarios/turtlebot.toml run by
`swarm up --robots` against the simulated fleet (`swarm robots sim`) with pose latency and
noise; the follower must settle at 1.00 m +- 0.05 (the paper's hardware figure: 0.96-1.04 m;
docs/guides/robots.md).

Starts `swarm robots sim SCENARIO --robots FILE --latency L --pose-noise N` on a free local
port, then `swarm up SCENARIO --robots FILE` for the scenario's duration (400 s) on the
realtime clock, `--time-scale` times faster than the wall (the fleet runs its own clock as
fast: its latency and command timeout are in the run's seconds), Ctrl-Cs the fleet at the
end and reads the run's results.

    python benchmarks/robots_turtlebot.py                             # 400 s of wall time
    python benchmarks/robots_turtlebot.py --time-scale 4              # 100 s
    python benchmarks/robots_turtlebot.py --scenario scenarios/case2.toml --robots scenarios/robots/case2.toml

Prints per agent its final radius (the distance to the target at the end), its mean, min
and max over the last --tail s and the expected radius, the same for `swarm sim` of the
scenario (no robots) for comparison, the pose ages the world measured, and the fleet's
report (a zero twist stopped every robot). Exit 0 when every follower's final radius is
within --tolerance (relative; 0.05 = 1.00 m +- 0.05 for the turtlebot) of its expected
radius, 1 otherwise or when a process failed.
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

import swarm  # noqa: E402
from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def with_endpoint(robots: Path, endpoint: str, out: Path) -> Path:
    """A copy of the robots file whose [ros2] connect is `endpoint`."""
    text = robots.read_text()
    text, n = re.subn(r'(?m)^connect\s*=\s*"[^"]*"', f'connect = "{endpoint}"', text)
    if n != 1:
        raise SystemExit(f"{robots}: expected one `connect = ...` line in [ros2]")
    out.write_text(text)
    return out


def radii(x: np.ndarray, y: np.ndarray, target: tuple[float, float]) -> np.ndarray:
    return np.hypot(x - target[0], y - target[1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "turtlebot.toml")
    ap.add_argument("--robots", type=Path, default=ROOT / "scenarios" / "robots" / "turtlebot.toml")
    ap.add_argument("--duration", type=float, default=None, help="run seconds (default: the scenario's)")
    ap.add_argument("--time-scale", type=float, default=1.0, help="run seconds per wall second (default 1)")
    ap.add_argument("--latency", type=float, default=0.03, help="s from a pose's measurement to its publication")
    ap.add_argument("--pose-noise", type=float, default=0.01, help="m (yaw: / 0.2 m rad); default 0.01")
    ap.add_argument("--seed", type=int, default=0, help="the noise's seed")
    ap.add_argument(
        "--quantize",
        type=float,
        default=0.0,
        help="the fleet truncates commands to steps of this (TurtleBot3's firmware: 0.01); default 0: none",
    )
    ap.add_argument("--tail", type=float, default=50.0, help="s at the end for the radius statistics")
    ap.add_argument("--tolerance", type=float, default=0.05, help="relative, of each follower's expected radius")
    ap.add_argument("--out", type=Path, default=None, help="the run's directory (default: a temporary one)")
    args = ap.parse_args()

    scenario = load_scenario(args.scenario)
    duration = args.duration or scenario.run.duration
    work = Path(tempfile.mkdtemp(prefix="robots-bench-"))
    out = args.out or work / "run"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robots = with_endpoint(args.robots, endpoint, work / "robots.toml")
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    swarm_cmd = [sys.executable, "-m", "swarm"]

    fleet_log = work / "fleet.log"
    fleet_cmd = [
        *swarm_cmd,
        "robots",
        "sim",
        str(args.scenario),
        "--robots",
        str(robots),
        "--latency",
        str(args.latency),
        "--pose-noise",
        str(args.pose_noise),
        "--seed",
        str(args.seed),
        "--time-scale",
        str(args.time_scale),
        "--quantize",
        str(args.quantize),
    ]
    up_cmd = [
        *swarm_cmd,
        "up",
        str(args.scenario),
        "--robots",
        str(robots),
        "--duration",
        str(duration),
        "--time-scale",
        str(args.time_scale),
        "--out",
        str(out),
        "--no-plots",
        "--force",
    ]
    print(f"fleet: {' '.join(fleet_cmd[2:])}", flush=True)
    with open(fleet_log, "w") as log:
        fleet = subprocess.Popen(fleet_cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        if not wait_until(lambda: fleet.poll() is not None or "fleet ready" in fleet_log.read_text(), 60, 0.1):
            print("the fleet did not get ready within 60 s", file=sys.stderr)
            return ExitCode.FAILED
        if fleet.poll() is not None:
            print(f"the fleet exited ({fleet.returncode}):\n{fleet_log.read_text()}", file=sys.stderr)
            return ExitCode.FAILED
        print(f"run:   {' '.join(up_cmd[2:])}", flush=True)
        t0 = time.monotonic()
        up = subprocess.run(up_cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        wall = time.monotonic() - t0
    finally:
        if fleet.poll() is None:
            fleet.send_signal(signal.SIGINT)
        try:
            fleet.wait(30)
        except subprocess.TimeoutExpired:
            fleet.kill()
            fleet.wait()
    print(f"swarm up exited {up.returncode} after {wall:.1f} s of wall time")
    if up.returncode != ExitCode.OK:
        print(up.stdout[-4000:], file=sys.stderr)
        return ExitCode.FAILED

    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "trajectory.npz") as z:
        t, x, y, ids = z["t"], z["x"], z["y"], [int(i) for i in z["ids"]]
    target = (scenario.target.x, scenario.target.y)
    sim = swarm.simulate(args.scenario, duration=duration)
    st, sx, sy = sim.arrays["t"], sim.arrays["x"], sim.arrays["y"]
    sim_ids = [int(i) for i in sim.arrays["ids"]]
    tail, sim_tail = t >= t[-1] - args.tail, st >= st[-1] - args.tail
    print(
        f"\n{scenario.name}: {duration:g} s at time scale {args.time_scale:g}, latency {args.latency:g} s, "
        f"pose noise {args.pose_noise:g} m, fleet quantize {args.quantize:g}; robots world vs swarm sim "
        f"(radius in m; last {args.tail:g} s: mean [min, max])"
    )
    ok = True
    for k, aid in enumerate(ids):
        a = summary["agents"][str(aid)]
        r = radii(x[:, k], y[:, k], target)
        j = sim_ids.index(aid)
        rs = radii(sx[:, j], sy[:, j], target)
        expected = a["expected_radius"]
        line = (
            f"  agent {aid} {a['role']:<8} final {r[-1]:.4f}  tail {r[tail].mean():.4f} "
            f"[{r[tail].min():.4f}, {r[tail].max():.4f}]   sim final {rs[-1]:.4f}  tail {rs[sim_tail].mean():.4f}"
            f"   expected {expected if expected is not None else '-'}"
        )
        if a["role"] == "follower" and expected is not None:
            within = abs(r[-1] - expected) <= args.tolerance * expected
            ok &= within
            line += f"   {'OK' if within else 'OFF'} (+-{args.tolerance * expected:.3f})"
        print(line)
    print(f"converged (the world's test): {summary['converged']}")
    for aid, fig in sorted(summary.get("robots", {}).get("agents", {}).items()):
        print(
            f"  robot {aid}: {fig['poses']} poses, {fig['twists']} twists; pose age max {fig['pose_age_max']:.3f} s, "
            f"median {fig['pose_age_p50']:.3f} s (run s); stale spells {fig['stale_spells']}"
        )
    report = [line for line in fleet_log.read_text().splitlines() if re.match(r"robot \d+: \d+ commands", line)]
    print("fleet:\n  " + "\n  ".join(report))
    if not all("stopped by a zero twist" in line for line in report) or len(report) != len(ids):
        print("a robot was not left stopped by a zero twist", file=sys.stderr)
        ok = False
    return ExitCode.OK if ok else ExitCode.FAILED


if __name__ == "__main__":
    sys.exit(main())
