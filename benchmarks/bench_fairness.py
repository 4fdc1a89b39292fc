"""Two fault experiments (docs/benchmarks.md#fairness, #stalls), each a real `swarm up` on case 2, printing figures:

- `flap`: realtime, 40 s; agent 3 is SIGKILLed mid-run, then a session holding agent 3's
  identity declares and undeclares its liveliness token --toggles times as fast as it can.
  Prints the other agents' staleness_max_ticks, commands dropped (flooded_messages), the
  world's over_limit and the size of summary.json. --toggles 0 is the clean run.
- `stall`: lockstep, 60 s; the world is SIGSTOPped --stop s mid-run. Prints missed ticks
  per agent, the largest distance from `swarm sim` of the same scenario (m) and
  `reproducible`.

    python benchmarks/bench_fairness.py flap --toggles 100000
    python benchmarks/bench_fairness.py stall --stop 5

--src runs another checkout of the code (its directory goes first on PYTHONPATH, also for
the world and agent processes), e.g. a clone of an older commit, for before/after figures.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from swarm.contracts import credentials, wire
from swarm.contracts.transport import open_client

ROOT = Path(__file__).resolve().parent.parent


def _start(src: Path, rt: Path, out: Path, *args: str) -> subprocess.Popen:
    env = {**os.environ, "SWARM_RUNTIME_DIR": str(rt), "PYTHONPATH": str(src)}
    return subprocess.Popen(
        [sys.executable, "-m", "swarm", "up", "scenarios/case2.toml", "--out", str(out), "--no-plots", *args],
        cwd=src,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


def _credentials(rt: Path, up: subprocess.Popen):

    t_end = time.monotonic() + 120
    while time.monotonic() < t_end and up.poll() is None:
        found = list(rt.glob("*.cred"))
        if found:
            return credentials.read(found[0])
        time.sleep(0.05)
    raise SystemExit(f"the run did not start: {up.stdout.read() if up.poll() is not None else ''}")


def _info(session, run: str) -> dict | None:

    for r in session.get(wire.world_info_key(run), timeout=2.0):
        if r.ok:
            return wire.decode_info(r.ok.payload.to_bytes())
    return None


def flap(src: Path, toggles: int, tmp: Path) -> None:

    rt, out = tmp / "rt", tmp / "flap"
    rt.mkdir(mode=0o700)
    os.environ["SWARM_RUNTIME_DIR"] = str(rt)
    up = _start(src, rt, out, "--clock", "realtime", "--duration", "40")
    creds = _credentials(rt, up)
    op = open_client(creds.endpoint, 5000, creds)
    try:
        while not (_info(op, creds.run) or {}).get("started"):
            time.sleep(0.2)
        time.sleep(3)
        os.kill(_info(op, creds.run)["agents"]["3"]["pid"], signal.SIGKILL)
        time.sleep(2)
        rogue = open_client(creds.endpoint, 5000, creds, user="agent-3")
        key = wire.agent_key(creds.run, 3, "alive")
        t0 = time.monotonic()
        for _ in range(toggles):
            rogue.liveliness().declare_token(key).undeclare()
        print(f"{toggles} toggles of agent 3's token in {time.monotonic() - t0:.1f} s", flush=True)
        rogue.close()
    finally:
        op.close()
    up.communicate(timeout=600)
    s = json.loads((out / "summary.json").read_text())
    others = {k: a for k, a in s["agents"].items() if k != "3"}
    print(
        f"exit {up.returncode}; summary.json {(out / 'summary.json').stat().st_size / 1e3:.0f} KB, "
        f"{len(s['events'])} events; over_limit {s.get('over_limit')}"
    )
    print("others' staleness_max_ticks:", {k: a.get("staleness_max_ticks") for k, a in others.items()})
    print("others' commands dropped (flooded_messages):", {k: a.get("flooded_messages") for k, a in others.items()})
    a3 = s["agents"]["3"]
    print(f"agent 3: joins {a3['joins']}, drops {a3['drops']}, unwritten {a3.get('churn_events_unwritten')}")


def stall(src: Path, stop: float, tmp: Path) -> None:
    rt, out, sim = tmp / "rt", tmp / "up", tmp / "sim"
    rt.mkdir(mode=0o700)
    up = _start(src, rt, out, "--clock", "lockstep", "--duration", "60")
    world = _credentials(rt, up).pid
    time.sleep(4.0)
    os.kill(world, signal.SIGSTOP)
    time.sleep(stop)
    os.kill(world, signal.SIGCONT)
    up.communicate(timeout=900)
    env = {**os.environ, "SWARM_RUNTIME_DIR": str(rt), "PYTHONPATH": str(src)}
    subprocess.run(
        [
            sys.executable,
            "-m",
            "swarm",
            "sim",
            "scenarios/case2.toml",
            "--out",
            str(sim),
            "--duration",
            "60",
            "--no-plots",
        ],
        cwd=src,
        env=env,
        capture_output=True,
        check=True,
    )
    a, b = np.load(out / "trajectory.npz"), np.load(sim / "trajectory.npz")
    d = float(np.nanmax(np.hypot(a["x"] - b["x"], a["y"] - b["y"])))
    s = json.loads((out / "summary.json").read_text())
    print(
        f"exit {up.returncode}; world stopped {stop:g} s; missed ticks "
        f"{ {k: v['missed_ticks'] for k, v in s['agents'].items()} }; largest distance from swarm sim {d:.3g} m; "
        f"reproducible {s.get('reproducible')} {s.get('not_reproducible') or ''}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("experiment", choices=("flap", "stall"))
    ap.add_argument("--toggles", type=int, default=100_000, help="flap: token declare/undeclare pairs")
    ap.add_argument("--stop", type=float, default=5.0, help="stall: s the world is SIGSTOPped")
    ap.add_argument("--src", type=Path, default=ROOT, help="the checkout to run (default: this one)")
    args = ap.parse_args()
    src = args.src.resolve()
    sys.path.insert(0, str(src))
    with tempfile.TemporaryDirectory(prefix="swarm-fair-") as d:
        if args.experiment == "flap":
            flap(src, args.toggles, Path(d))
        else:
            stall(src, args.stop, Path(d))


if __name__ == "__main__":
    main()
