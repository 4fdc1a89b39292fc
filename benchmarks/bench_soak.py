"""Soak: a long realtime run with agents killed and brought back over and over: the world's RSS
must not rise steadily (docs/benchmarks.md#soak).

Starts `swarm up` on a shipped scenario on the realtime clock, long enough for --minutes
of wall time, and every 60 / --cycles-per-minute s SIGKILLs one agent (`swarm kill ID`,
which waits until the world drops it) and brings it back (`swarm spawn --id ID`: a
dropped id rejoins from the pose it had, docs/reference/protocol.md#drop-rejoin), taking the agents in turn.
Meanwhile it samples the world process's RSS every --sample s. When the run has ended by
itself it reads the results (docs/reference/outputs.md): every tick must be a row of
trajectory.npz (ticks + 1 rows, consecutive times).

    python benchmarks/bench_soak.py --minutes 9 --cycles-per-minute 5
    python benchmarks/bench_soak.py --minutes 60 --cycles-per-minute 2 --out /tmp/soak60   # ~118 cycles

Prints: cycles done, rows expected/recorded, world RSS at the end of the warm-up (5 min)
and at the end, the drift after the warm-up in %, and the least-squares slope of RSS
against wall time after the warm-up (KB/min); with --cycles-per-minute 0 the same run
without faults, the control. The samples go to <out>/soak.json. Exit 1 when rows are
missing or the run did not complete; the RSS figures are read by people, not asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from up_banner import wait_banner  # noqa: E402

from swarm.contracts import credentials, wire  # noqa: E402
from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.contracts.transport import open_client  # noqa: E402
from swarm.contracts.vocabulary import EventKind, ExitCode  # noqa: E402
from swarm.runtime.procs import Group, wait_until  # noqa: E402


def rss_kb(pid: int) -> int:
    """VmRSS of `pid` in KB (from /proc, as `ps` shows it)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise ProcessLookupError(pid)


def slope_kb_per_min(samples: list[tuple[float, int]]) -> float | None:
    """Least-squares slope of RSS (KB) against wall time, in KB per minute."""
    if len(samples) < 3:
        return None
    t = np.array([s[0] for s in samples]) / 60.0
    m = np.array([s[1] for s in samples], dtype=float)
    return float(np.polyfit(t, m, 1)[0])


def rss_at(samples: list[tuple[float, int]], t: float) -> int:
    """The sample nearest to `t` s."""
    return min(samples, key=lambda s: abs(s[0] - t))[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=9.0, help="wall minutes of the run (default 9)")
    ap.add_argument(
        "--cycles-per-minute",
        type=float,
        default=5.0,
        help="kill/spawn cycles per wall minute (0: none, the control run; default 5)",
    )
    ap.add_argument("--out", type=Path, default=None, help="the run's output directory (default: a new temp dir)")
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "case2.toml")
    ap.add_argument("--time-scale", type=float, default=2.0, help="simulated s per wall s (default 2)")
    ap.add_argument("--agents", default="2,3,4,5", help="ids to kill, in turn (default the followers of case 2)")
    ap.add_argument("--sample", type=float, default=3.0, help="wall s between RSS samples (default 3)")
    ap.add_argument(
        "--warmup",
        type=float,
        default=5.0,
        help="wall minutes before the drift is measured (default 5; half the run if that leaves less than a minute)",
    )
    a = ap.parse_args()
    # Stopped early (Ctrl-C, or SIGTERM: a background job of a shell ignores SIGINT), the run is
    # still stopped the way `swarm up` wants (SIGINT: results written) and its group ended.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))

    scen = load_scenario(a.scenario)
    dt = scen.run.dt
    duration = a.minutes * 60.0 * a.time_scale
    ticks = round(duration / dt)
    work = Path(tempfile.mkdtemp(prefix="swsoak-"))
    out = a.out or (work / "run")
    # the CLI and the run's processes import this checkout's swarm, world and agents (as this script does)
    env = {
        **os.environ,
        "SWARM_RUNTIME_DIR": str(work / "rt"),
        "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
    }
    victims = [int(x) for x in a.agents.split(",") if x.strip()]
    warm = (a.warmup if a.minutes >= a.warmup + 1.0 else a.minutes / 2) * 60.0

    group = Group(session=True)
    up_log = work / "up.log"
    with open(up_log, "wb") as log:
        up = group.start(
            [
                sys.executable,
                "-m",
                "swarm",
                "up",
                str(a.scenario),
                "--out",
                str(out),
                "--force",
                "--clock",
                "realtime",
                "--time-scale",
                str(a.time_scale),
                "--duration",
                str(duration),
                "--no-plots",
            ],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    samples: list[tuple[float, int]] = []
    cycles = failed = 0
    stop = threading.Event()
    try:
        got = wait_banner(up_log, 60)
        if not got:
            print("swarm up printed no banner; see", up_log)
            return ExitCode.FAILED
        run, endpoint = got
        env["SWARM_RUN"] = run
        cred_file = work / "rt" / f"{run}{credentials.SUFFIX}"
        if not wait_until(cred_file.exists, 30, 0.1):
            print("the world wrote no credentials; see", up_log)
            return ExitCode.FAILED
        ses = open_client(endpoint, timeout_ms=5000, creds=credentials.read(cred_file))
        try:

            def info():
                for r in ses.get(wire.world_info_key(run), timeout=2.0):
                    if r.ok:
                        return wire.decode_info(r.ok.payload.to_bytes())
                return None

            first = wait_until(lambda: (i := info()) and i.get("started") and i, 120, 0.2)
        finally:
            ses.close()  # one query, then no session of ours on the hub: the soak measures the run's own
        if not first:
            print("the run did not start; see", up_log)
            return ExitCode.FAILED
        pid = first["pid"]
        t0 = time.monotonic()
        end = t0 + a.minutes * 60.0
        print(
            f"run {run}: world pid {pid}, {duration:g} simulated s at x{a.time_scale:g}, "
            f"{ticks + 1} rows expected; output {out}",
            flush=True,
        )

        def sampler():  # while the run ticks (not while it writes its results at the end)
            while not stop.is_set() and time.monotonic() < end - 1.0:
                try:
                    samples.append((time.monotonic() - t0, rss_kb(pid)))
                except (ProcessLookupError, FileNotFoundError):
                    return
                stop.wait(a.sample)

        th = threading.Thread(target=sampler, daemon=True)
        th.start()

        def cli(*args) -> bool:
            p = subprocess.run(
                [sys.executable, "-m", "swarm", *args],
                env=env,
                stdin=subprocess.DEVNULL,
                capture_output=True,
                text=True,
                timeout=60,
                check=False,
            )
            if p.returncode != ExitCode.OK:
                print(
                    f"  swarm {' '.join(args)}: exit {p.returncode}: {(p.stderr or p.stdout).strip()[-300:]}",
                    flush=True,
                )
            return p.returncode == ExitCode.OK

        period = 60.0 / a.cycles_per_minute if a.cycles_per_minute > 0 else None
        next_at = t0 + (period or 0.0)
        k = 0
        last_print = t0
        while up.poll() is None:
            now = time.monotonic()
            # no new cycle in the last 20 s: the run ends with every agent back
            if period is not None and now >= next_at and now < end - 20.0:
                aid = victims[k % len(victims)]
                k += 1
                if cli("kill", str(aid)) and cli("spawn", "--id", str(aid)):
                    cycles += 1
                else:
                    failed += 1
                next_at += period
                if next_at < time.monotonic():  # fell behind (a slow machine): no burst of catch-up cycles
                    next_at = time.monotonic() + period
            if now - last_print >= 60.0 and samples:
                last_print = now
                print(
                    f"  {(now - t0) / 60:5.1f} min: {cycles} cycles, world RSS {samples[-1][1] / 1024:.1f} MB",
                    flush=True,
                )
            time.sleep(0.1)
        up_code = up.wait()
        stop.set()
        th.join(5)
    finally:
        stop.set()
        if up.poll() is None:
            group.signal(signal.SIGINT)
        group.stop(grace=30.0)

    # -- what was recorded ------------------------------------------------------------------
    rows = 0
    gaps = None
    summary = {}
    try:
        z = np.load(out / "trajectory.npz")
        t = z["t"]
        rows = len(t)
        gaps = int(np.sum(np.abs(np.diff(t) - dt) > 1e-6 * max(1.0, dt)))
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError, KeyError) as e:
        print(f"cannot read the results in {out}: {e}")
    drops = sum(1 for e in summary.get("events", []) if e["kind"] == EventKind.DROP)
    rejoins = sum(1 for e in summary.get("events", []) if e["kind"] == EventKind.REJOIN)

    after = [s for s in samples if s[0] >= warm]
    r_warm = rss_at(samples, warm) if samples else 0
    r_end = samples[-1][1] if samples else 0
    drift = (r_end - r_warm) / r_warm * 100.0 if r_warm else float("nan")
    slope = slope_kb_per_min(after)
    slope_all = slope_kb_per_min([s for s in samples if s[0] >= 60.0])
    per_cycle = slope / a.cycles_per_minute if slope is not None and a.cycles_per_minute > 0 else None
    print(f"swarm up exit {up_code}; completed {summary.get('completed')}")
    print(f"cycles done: {cycles} (failed {failed}); drops {drops}, rejoins {rejoins} in summary.json")
    print(f"rows expected/recorded: {ticks + 1}/{rows} (time gaps {gaps})")
    print(
        f"world RSS: {samples[0][1] / 1024:.1f} MB at start, {r_warm / 1024:.1f} MB at {warm / 60:g} min, "
        f"{r_end / 1024:.1f} MB at end ({samples[-1][0] / 60:.1f} min)"
        if samples
        else "world RSS: no sample"
    )
    print(
        f"drift after {warm / 60:g} min: {drift:+.2f}%; slope after {warm / 60:g} min: "
        + (f"{slope:+.1f} KB/min" if slope is not None else "n/a")
        + (f", after 1 min: {slope_all:+.1f} KB/min" if slope_all is not None else "")
        + (f" (~{per_cycle:+.1f} KB per cycle if it all came from the cycles)" if per_cycle is not None else "")
    )
    try:
        (out / "soak.json").write_text(
            json.dumps(
                {
                    "minutes": a.minutes,
                    "cycles_per_minute": a.cycles_per_minute,
                    "time_scale": a.time_scale,
                    "scenario": str(a.scenario),
                    "cycles": cycles,
                    "failed_cycles": failed,
                    "rows_expected": ticks + 1,
                    "rows": rows,
                    "gaps": gaps,
                    "rss_warm_kb": r_warm,
                    "rss_end_kb": r_end,
                    "drift_pct": drift,
                    "slope_kb_per_min": slope,
                    "samples": samples,
                },
                indent=1,
            )
            + "\n"
        )
    except OSError:
        pass
    ok = rows == ticks + 1 and gaps == 0 and up_code == ExitCode.OK
    return ExitCode.OK if ok else ExitCode.FAILED


if __name__ == "__main__":
    raise SystemExit(main())
