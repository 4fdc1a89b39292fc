"""Where a lockstep tick's CPU goes: `swarm up` beside the bare-zenoh peer, thread by thread
(a benchmark, not a test).

    python benchmarks/bench_budget.py [--sizes 6,20] [--reps 2] [--window 4] [--both] [--json FILE]

For each N (unlimited sensing), interleaved and repeated: the bare-zenoh peer of
benchmarks/peers (a world and N agents on swarm's own transport, doing nothing but the
exchange) and `swarm up` of bench_runtime.py's ring scenario; with --both also `swarm up`
with the world and the agents doing no work (benchmarks/ablation, "both": what the
runtime's shells cost alone). It reads every thread's CPU time (/proc) of the world and of
two agents, for the bare peer over all its measured ticks, for `swarm up` over --window s
in the middle of the run (the ticks made meanwhile asked of the world, `swarm.connect`),
and prints microseconds of CPU per tick by kind of thread:

- world main:    the world's Python main thread (swarm: the tick loop, sensing, encoding,
                 recording, the step; bare: waiting for answers and sending frames);
- world python:  the world's other Python threads (zenoh's callbacks into Python);
- world zenoh:   the world's zenoh runtime threads (Rust: rx-*, tx-*, acc-*, app-*);
- agent python:  one agent's Python threads (its frame callback: decode, choose, law, send);
- agent zenoh:   one agent's zenoh runtime threads;
- total:         world + N agents, every thread.

On a machine with C cores a tick cannot be shorter than total / C: the table prints that
ceiling beside the ticks per second measured. Only processes started here are signalled
(bench_runtime.py's Tracked).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_runtime import (  # noqa: E402
    DT,
    PY,
    REPO,
    Tracked,
    all_exited,
    is_agent,
    is_world,
    log,
    scenario_toml,
    thread_cpu,
    world_started,
)

from swarm.api.live import connect  # noqa: E402
from swarm.contracts.errors import SwarmError  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402

PEER = REPO / "benchmarks" / "peers" / "zenoh_peer.py"
ABLATION = REPO / "benchmarks" / "ablation"
KINDS = ("world main", "world python", "world zenoh", "agent python", "agent zenoh")
ZENOH_THREADS = ("rx-", "tx-", "acc-", "app-", "net-")


def kind_of(proc: str, tid: int, pid: int, name: str) -> str:
    if not name.startswith(ZENOH_THREADS):
        return f"{proc} main" if proc == "world" and tid == pid else f"{proc} python"
    return f"{proc} zenoh"


class Window:
    """Thread CPU of the world and of two agents between start() and stop(), and of every
    process of the run (the total)."""

    def __init__(self, world: psutil.Process, agents: list[psutil.Process]):
        self.world, self.agents = world, agents
        self.everyone = [world, *agents]

    def snap(self) -> tuple[float, dict[int, dict], float]:
        total = 0.0
        for p in self.everyone:
            try:
                t = p.cpu_times()
                total += t.user + t.system
            except psutil.NoSuchProcess:
                pass
        return time.monotonic(), {p.pid: thread_cpu(p) for p in [self.world, *self.agents[:2]]}, total

    def start(self) -> None:
        self.a = self.snap()

    def stop(self) -> dict:
        (t0, a, tot0), (t1, b, tot1) = self.a, self.snap()
        dt = t1 - t0
        kinds: dict[str, float] = dict.fromkeys(KINDS, 0.0)
        for p in [self.world, *self.agents[:2]]:
            proc = "world" if p is self.world else "agent"
            share = 1.0 if p is self.world else 0.5  # the mean of two agents
            for tid, (name, c1) in b.get(p.pid, {}).items():
                if tid in a.get(p.pid, {}):
                    kinds[kind_of(proc, tid, p.pid, name)] += share * (c1 - a[p.pid][tid][1]) / dt
        return {"seconds": dt, "cores": kinds, "total_cores": (tot1 - tot0) / dt}


def run_bare(n: int, ticks: int, work: Path, env: dict, tag: str) -> dict:
    """The bare peer: CPU from its first measured tick to its result (the peer's world then
    waits for the release file, its agents idle), over its measured ticks."""
    d = work / f"bare-{tag}"
    d.mkdir()
    result, measuring, release = d / "result.json", d / "measuring", d / "release"
    ep = f"unixsock-stream/{env['SWARM_RUNTIME_DIR']}/b{tag}.sock"
    argv = ["--n", str(n), "--k", str(n - 1), "--ticks", str(ticks), "--result", str(result)]
    argv += ["--measuring", str(measuring), "--release", str(release)]
    tr = Tracked()
    res: dict = {"system": "bare zenoh", "n": n, "ok": False}
    try:
        world = tr.spawn([PY, str(PEER), "world", ep, *argv], d / "world.log", env)
        time.sleep(0.3)  # the router listens before the clients connect
        agents = [
            tr.spawn([PY, str(PEER), "agent", ep, str(i)], d / f"agent-{i}.log", env, own_group=False) for i in range(n)
        ]
        if not wait_until(measuring.exists, 60, 0.005):
            res["error"] = f"never ticked; see {d}"
            return res
        w = Window(tr.seen[world.pid], [tr.seen[a.pid] for a in agents])
        w.start()
        if not wait_until(lambda: result.exists() or world.poll() is not None, 120 + ticks / 50, 0.005):
            res["error"] = f"no result; see {d}"
            return res
        res["window"] = w.stop()
        release.touch()
        r = json.loads(result.read_text())
        res["window"]["ticks"] = r["ticks"]
        res.update(ok=bool(r.get("ok")), ticks_per_second=r.get("ticks_per_second"))
        wait_until(all_exited([world]), 30)
    except (OSError, ValueError, KeyError) as e:
        res["error"] = f"{e}; see {d}"
    finally:
        tr.stop()
    return res


def world_tick(live) -> int:
    return int(live.info()["tick"])


def run_up(n: int, ticks: int, window: float, work: Path, env: dict, tag: str, ablate: str | None) -> dict:
    """`swarm up`: CPU over `window` s in the middle of the run, over the ticks the world
    says it made meanwhile (its info, asked just before and just after)."""
    d = work / f"up-{tag}"
    d.mkdir()
    toml = d / f"bench{n}.toml"
    toml.write_text(scenario_toml(n, None, ticks=ticks))
    out = d / "out"
    if ablate:
        path = os.pathsep.join(filter(None, (str(ABLATION), env.get("PYTHONPATH"))))
        env = {**env, "PYTHONPATH": path, "SWARM_ABLATE": ablate}
    tr = Tracked()
    res: dict = {"system": "swarm up" + (f" ({ablate}: no work)" if ablate else ""), "n": n, "ok": False}
    live = None
    try:
        up = tr.spawn(
            [PY, "-m", "swarm", "up", str(toml), "--out", str(out), "--duration", f"{ticks * DT:.6f}", "--no-plots"],
            d / "up.log",
            env,
        )
        if not wait_until(lambda: world_started(out) or up.poll() is not None, 120):
            res["error"] = f"never ticked; see {d}"
            return res
        kids = tr.discover(up)
        worlds, agents = [k for k in kids if is_world(k)], [k for k in kids if is_agent(k)]
        if not worlds or len(agents) != n:
            res["error"] = f"found {len(worlds)} world(s) and {len(agents)} of {n} agents; see {d}"
            return res
        live = connect()  # the only run in this benchmark's runtime directory
        k0, t0 = world_tick(live), time.monotonic()
        time.sleep(1.0)
        k1, t1 = world_tick(live), time.monotonic()
        rate = (k1 - k0) / (t1 - t0)
        left = (ticks - k1) / rate if rate > 0 else 0.0  # s of ticking left: the window in its middle
        time.sleep(max(0.0, (left - window) / 2))
        w = Window(worlds[0], agents)
        a = world_tick(live)
        w.start()
        time.sleep(window)
        res["window"] = w.stop()
        res["window"]["ticks"] = world_tick(live) - a
        live.close()
        live = None
        wait_until(all_exited([up]), 120 + ticks / 50)
        s = json.loads((out / "summary.json").read_text())
        res.update(ok=up.returncode == ExitCode.OK, ticks_per_second=s.get("ticks_per_second"))
    except (OSError, ValueError, KeyError, SwarmError) as e:
        res["error"] = f"{e}; see {d}"
    finally:
        if live is not None:
            live.close()
        tr.stop()
    return res


def per_tick(run: dict) -> dict[str, float]:
    """Microseconds of CPU per tick, by kind (total: every process of the run), over the
    ticks made in the measured window."""
    w = run["window"]
    per = w["seconds"] / w["ticks"]  # s per tick in the window
    out = {k: 1e6 * c * per for k, c in w["cores"].items()}
    out["total"] = 1e6 * w["total_cores"] * per
    return out


def table(runs: list[dict], cores: int) -> str:
    lines = []
    head = ["N", "system", "ticks/s", *KINDS, "total", f"ceiling ({cores} cores)"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + " --- |" * len(head))
    runs = [r for r in runs if r.get("ok") and r.get("ticks_per_second") and r["window"].get("ticks")]
    done = {(r["n"], r["system"]) for r in runs}
    keys = sorted(done, key=lambda k: (k[0], k[1] != "bare zenoh", k[1]))
    for n, system in keys:
        rs = [r for r in runs if r.get("ok") and (r["n"], r["system"]) == (n, system)]
        tps = statistics.median(r["ticks_per_second"] for r in rs)
        pt = {k: statistics.median(per_tick(r)[k] for r in rs) for k in (*KINDS, "total")}
        ceiling = cores * 1e6 / pt["total"]
        cells = [str(n), system, f"{tps:.0f}", *(f"{pt[k]:.0f}" for k in KINDS), f"{pt['total']:.0f}", f"{ceiling:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="6,20", help="agent counts, comma-separated (default 6,20)")
    ap.add_argument("--reps", type=int, default=2, help="runs of each system per N (default 2)")
    ap.add_argument("--window", type=float, default=4.0, help="s of CPU measured in each run (default 4)")
    ap.add_argument("--both", action="store_true", help="also swarm up with the world and agents doing no work")
    ap.add_argument("--json", type=Path, help="write every run to this JSON file")
    a = ap.parse_args(argv)
    try:
        sizes = [int(s) for s in a.sizes.split(",") if s]
    except ValueError:
        ap.error(f"--sizes: expected comma-separated integers, got {a.sizes!r}")
    if not sizes or min(sizes) < 2:
        ap.error("--sizes: at least one N, each 2 or more")
    rt = tempfile.mkdtemp(prefix="bb", dir="/tmp")  # short: Unix socket paths are limited to 108 bytes
    work = Path(tempfile.mkdtemp(prefix="swarm-budget-"))
    os.environ["SWARM_RUNTIME_DIR"] = rt  # this process asks the world its tick (run_up)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("SWARM_ABLATE", None)
    systems = ["bare", "swarm"] + (["both"] if a.both else [])
    runs: list[dict] = []
    try:
        for rep in range(a.reps):
            for n in sizes:
                ticks = max(2000, 150_000 // n)  # long enough for the window in the middle
                for s in systems[rep % len(systems) :] + systems[: rep % len(systems)]:
                    tag = f"{n}-{rep}-{s}"
                    log(f"[rep {rep + 1}/{a.reps}] N={n} {s} (load {os.getloadavg()[0]:.2f})")
                    if s == "bare":
                        r = run_bare(n, ticks, work, env, tag)
                    else:
                        r = run_up(n, ticks, a.window, work, env, tag, "both" if s == "both" else None)
                    r["rep"] = rep
                    runs.append(r)
                    log(f"  -> {r.get('ticks_per_second') or 0:.0f} ticks/s {r.get('error', '')}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(rt, ignore_errors=True)
    cores = os.cpu_count() or 1
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(
        f"\nCPU per tick in microseconds (medians of {a.reps}); {when}, commit {commit.strip()}, "
        f"{platform.processor() or platform.machine()}, {cores} cores, Python {platform.python_version()}"
    )
    if a.json:
        doc = {"when": when, "commit": commit.strip(), "cores": cores, "runs": runs}
        a.json.write_text(json.dumps(doc, indent=2) + "\n")
    print(table(runs, cores))
    return ExitCode.OK if runs and all(r.get("ok") for r in runs) else ExitCode.FAILED


if __name__ == "__main__":
    sys.exit(main())
