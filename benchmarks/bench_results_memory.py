"""The world's memory at the end of a long run, while it writes its results
(docs/benchmarks.md#results-memory): it should not grow with the run's length.

Starts `swarm up SCENARIO --out DIR --duration D` (by default on the lockstep clock, which
runs as fast as the machine allows; `--clock realtime --speed X` for the realtime clock),
finds the world process among its children and samples, from outside, its VmRSS every
--sample s and its VmHWM (peak RSS, /proc/PID/status) until it exits. The samples are split
at the end of ticking (summary.json's start_wall_time + wall_time): the peak while the run
ticks, and the peak over the whole life of the process (VmHWM), which includes reading the
recording back and writing trajectory.npz and summary.json.

    python benchmarks/bench_results_memory.py --minutes 20          # 120,000 ticks of case 2
    python benchmarks/bench_results_memory.py --minutes 60 --plots  # and the `swarm up` process drawing the plots
    PYTHONPATH=/tmp/before python benchmarks/bench_results_memory.py --root /tmp/before --minutes 20

`--root`: the checkout whose `swarm` the run imports (put first on PYTHONPATH for the CLI,
the world and the agents), to measure an older commit from a git worktree. Prints the
figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parent.parent


def status_kb(pid: int) -> dict[str, int]:
    """VmRSS and VmHWM of `pid` in KB."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                out[line.split(":")[0]] = int(line.split()[1])
    return out


def find_world(up: psutil.Process, timeout: float) -> psutil.Process | None:
    """The `python -m swarm world ...` child of `swarm up`."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            for p in up.children(recursive=True):
                cmd = p.cmdline()
                if "swarm" in cmd and "world" in cmd:
                    return p
        except psutil.Error:
            pass
        time.sleep(0.05)
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=20.0, help="simulated minutes of the run (default 20)")
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "case2.toml")
    ap.add_argument("--clock", default="lockstep", choices=("lockstep", "realtime"))
    ap.add_argument("--speed", type=float, default=None, help="realtime clock: simulated s per wall s")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout the run imports (default this one)")
    ap.add_argument("--out", type=Path, default=None, help="the run directory (default a new temp dir)")
    ap.add_argument("--plots", action="store_true", help="let `swarm up` draw the plots (its own peak is printed)")
    ap.add_argument("--sample", type=float, default=0.2, help="wall s between samples (default 0.2)")
    a = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="swresmem-"))
    out = a.out or work / "run"
    env = {
        **os.environ,
        "SWARM_RUNTIME_DIR": str(work / "rt"),
        "PYTHONPATH": os.pathsep.join([str(a.root), *filter(None, [os.environ.get("PYTHONPATH")])]),
    }
    which = subprocess.run(
        [sys.executable, "-c", "import swarm; print(swarm.__file__)"], env=env, capture_output=True, text=True
    ).stdout.strip()
    rev = subprocess.run(["git", "-C", str(a.root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    duration = a.minutes * 60.0
    cmd = [sys.executable, "-m", "swarm", "up", str(a.scenario), "--out", str(out), "--force"]
    cmd += ["--duration", str(duration), "--clock", a.clock]
    if a.speed is not None:
        cmd += ["--speed", str(a.speed)]
    if not a.plots:
        cmd.append("--no-plots")
    print(f"swarm from {which} ({rev.stdout.strip() or '?'}); {a.minutes:g} simulated min, clock {a.clock}", flush=True)
    samples: list[tuple[float, int]] = []  # (unix s, world VmRSS KB)
    peak = {"world": 0, "up": 0}
    t_start = time.time()
    with open(work / "up.log", "wb") as log:
        up = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
    up_ps = psutil.Process(up.pid)
    world = find_world(up_ps, 60.0)
    if world is None:
        up.wait()
        print("no world process found; see", work / "up.log")
        return 1
    wpid = world.pid
    done = threading.Event()

    def watch_up():  # the `swarm up` process (it draws the plots after the world has ended)
        while not done.is_set():
            try:
                peak["up"] = max(peak["up"], status_kb(up.pid).get("VmHWM", 0))
            except (OSError, ValueError):
                return
            done.wait(a.sample)

    th = threading.Thread(target=watch_up, daemon=True)
    th.start()
    while True:
        try:
            st = status_kb(wpid)
        except (OSError, ValueError):
            break
        if not st:  # a zombie: its memory is gone
            break
        samples.append((time.time(), st.get("VmRSS", 0)))
        peak["world"] = max(peak["world"], st.get("VmHWM", 0))
        time.sleep(a.sample)
    code = up.wait()
    done.set()
    th.join(5)
    wall = time.time() - t_start
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError) as e:
        print(f"no summary.json in {out}: {e}; see {work / 'up.log'}")
        return 1
    ticks_end = (summary.get("start_wall_time") or t_start) + (summary.get("wall_time") or 0.0)
    ticking = [r for t, r in samples if t <= ticks_end]
    after = [r for t, r in samples if t > ticks_end]
    npz = out / "trajectory.npz"
    print(
        f"swarm up exit {code}; {summary.get('ticks')} ticks in {summary.get('wall_time', 0):.0f} s of ticking, "
        f"{wall:.0f} s in all; trajectory.npz {npz.stat().st_size / 2**20:.1f} MB, "
        f"recording.mcap {(out / 'recording.mcap').stat().st_size / 2**20:.1f} MB"
    )
    print(
        f"world RSS: peak while ticking {max(ticking, default=0) / 1024:.1f} MB, "
        f"peak sampled after ticking {max(after, default=0) / 1024:.1f} MB, "
        f"VmHWM (whole life, results included) {peak['world'] / 1024:.1f} MB"
    )
    if a.plots:
        print(f"swarm up process (draws the plots) VmHWM {peak['up'] / 1024:.1f} MB")
    print(f"run directory: {out}")
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
