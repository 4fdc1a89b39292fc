"""`swarm up` side by side with the same lockstep job on other middleware (a benchmark).

    python benchmarks/peers/run.py [--n 6,20,50] [--range-n 100] [--range-k 8] [--reps 3]
                                   [--ticks 2000] [--systems swarm,zenoh,zmq,dds,dora]
                                   [--smoke] [--json FILE] [--keep]

The peers (install: `pip install pyzmq cyclonedds dora-rs dora-rs-cli`; eclipse-zenoh comes
with swarm) run the job of common.py: a world and N agent processes, each tick a frame of
52 + 30*K bytes to every agent and one truth message, a 38-byte answer from each, the next
tick when all answered; nothing else. `swarm up` runs a generated lockstep scenario of N
agents on a ring (benchmarks/bench_runtime.py's scenario_toml and run_swarm): unlimited
sensing for each N of --n (K = N - 1), and for --range-n a sensing range under which each
agent senses about --range-k others (the peers then send K = --range-k contacts).

For each repetition, each size, each system (the order rotated every repetition, so the
systems are interleaved): ticks/s over --ticks ticks after a warm-up, p50/p99 of a tick's
duration (peers: from sending the first frame to the last answer, in the world; swarm up:
summary.json's `tick_ms`, from its first frame going out to the end of its record and step,
over every tick, the warm-up included, as its ticks/s), CPU per
tick (user + system time of every process of the run: world, agents, and dora's daemon or
swarm up's launcher, over the measured ticks / ticks), RSS (sum over those processes, the
peak of each). The table gives every repetition's ticks/s and the medians of the rest, with
the date, commit, machine and the load average before each run (the machine may be shared).

Every process is started in a process group of its own (bench_runtime.Tracked) and ended
through it; nothing else is signalled. --smoke: N = 3, 50 ticks, bare zenoh, zmq and
swarm up, one repetition (well under 30 s).
"""

from __future__ import annotations

import argparse
import importlib.util
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
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.bench_runtime import DT, Tracked, all_exited, run_swarm  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402

PY = sys.executable
SYSTEMS = ("swarm", "zenoh", "zmq", "dds", "dora")
LABELS = {
    "swarm": "`swarm up` (the whole runtime)",
    "zenoh": "bare zenoh",
    "zmq": "zmq over ipc",
    "dds": "Cyclone DDS",
    "dora": "dora-rs (Python nodes)",
}
NEEDS = {"zmq": ("zmq", "pyzmq"), "dds": ("cyclonedds", "cyclonedds"), "dora": ("dora", "dora-rs")}
MB = 1024 * 1024


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def missing(system: str) -> str | None:
    """Why `system` cannot run here (None: it can)."""
    if system in NEEDS:
        module, dist = NEEDS[system]
        if importlib.util.find_spec(module) is None:
            return f"{dist} is not installed (pip install {dist})"
    if system == "dora" and dora_cli() is None:
        return "the dora command is not installed (pip install dora-rs-cli)"
    return None


def dora_cli() -> str | None:
    return shutil.which("dora", path=str(Path(PY).parent)) or shutil.which("dora")


class Meter:
    """CPU time and peak RSS of every process of a run (the Popens and their descendants)."""

    def __init__(self, tr: Tracked):
        self.tr = tr
        self.rss: dict[int, float] = {}
        self.cpu0: dict[int, float] = {}
        self.t0 = 0.0

    def procs(self) -> list[psutil.Process]:
        for p in self.tr.popens:
            if p.poll() is None:
                self.tr.discover(p)
        return self.tr.alive()

    def cpu(self) -> dict[int, float]:
        out = {}
        for pr in self.procs():
            try:
                t = pr.cpu_times()
                out[pr.pid] = t.user + t.system
                self.rss[pr.pid] = max(self.rss.get(pr.pid, 0.0), pr.memory_info().rss / MB)
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                pass
        return out

    def start(self) -> None:
        self.cpu0, self.t0 = self.cpu(), time.monotonic()

    def stop(self) -> tuple[float, float, int]:
        """(CPU s of every process over the window, window s, processes)."""
        c1, t1 = self.cpu(), time.monotonic()
        return sum(v - self.cpu0[k] for k, v in c1.items() if k in self.cpu0), t1 - self.t0, len(c1)


def run_peer(system: str, n: int, k: int, ticks: int, warmup: int, work: Path, env: dict, tag: str) -> dict:
    d = work / f"{system}-{tag}"
    d.mkdir()
    result, measuring, release = d / "result.json", d / "measuring", d / "release"
    world_argv = ["--n", str(n), "--k", str(k), "--ticks", str(ticks), "--warmup", str(warmup)]
    world_argv += ["--result", str(result), "--measuring", str(measuring), "--release", str(release)]
    res: dict = {"system": system, "n": n, "k": k, "ok": False, "load1": os.getloadavg()[0]}
    tr = Tracked()
    meter = Meter(tr)
    script = str(HERE / f"{system}_peer.py")
    try:
        if system == "dora":
            flow = d / "dataflow.yml"
            subprocess.run([PY, script, "yaml", str(flow), *world_argv], check=True, cwd=d)
            cli = dora_cli()
            assert cli is not None
            main = tr.spawn([cli, "run", str(flow)], d / "dora.log", env)
        else:
            where = {
                "zenoh": [f"unixsock-stream/{env['SWARM_RUNTIME_DIR']}/p{tag}.sock"],
                "zmq": [str(d)],
                "dds": [],
            }[system]
            main = tr.spawn([PY, script, "world", *where, *world_argv], d / "world.log", env)
            if system == "zenoh":
                time.sleep(0.3)  # the router listens before the clients connect (they would retry)
            for i in range(n):
                tr.spawn([PY, script, "agent", *where, str(i)], d / f"agent-{i}.log", env, own_group=False)
        state = {"measuring": False, "done": False}

        def sample() -> None:
            if not state["measuring"] and measuring.exists():
                state["measuring"] = True
                meter.start()
            elif state["measuring"] and not state["done"] and result.exists():
                state["done"] = True
                res["cpu_s"], res["window_s"], res["processes"] = meter.stop()
                release.touch()
            elif state["measuring"] and not state["done"]:
                meter.cpu() if time.monotonic() - meter.t0 > 0.5 and not meter.rss else None

        wait_until(all_exited([main], sample), 90 + ticks / 5, 0.01)
        wait_until(all_exited(tr.popens), 15, 0.05)
    finally:
        tr.stop()
    try:
        r = json.loads(result.read_text())
    except (OSError, ValueError) as e:
        res["error"] = f"no result ({e}); see {d}"
        return res
    res.update(r)
    if r.get("ok") and "cpu_s" in res:
        res["cpu_ms_per_tick"] = 1e3 * res["cpu_s"] / (res["window_s"] * r["ticks_per_second"])
        res["rss_mb"] = sum(meter.rss.values())
    return res


def run_up(n: int, k: int | None, ticks: int, warmup: int, work: Path, env: dict, tag: str) -> dict:
    """bench_runtime.run_swarm: `swarm up` of the generated scenario for ticks + warmup ticks."""
    s = run_swarm(n, ticks + warmup, work, env, tag, neighbours=k)
    res: dict = {"system": "swarm", "n": n, "k": k if k is not None else n - 1, **s}
    res.pop("memory_agents", None)
    cpu, tps = s.get("cpu"), s.get("ticks_per_second")
    if s.get("ok") and cpu and tps:
        res["cpu_ms_per_tick"] = 1e3 * sum(cpu["cpu_s"].values()) / (cpu["window_s"] * tps)
    agents, world = (s.get("memory_agents") or {}).get("rss"), (s.get("memory_world") or {}).get("rss")
    if agents and world:
        res["rss_mb"] = agents["mean_mb"] * agents["n"] + world["max_mb"]  # the launcher's is not sampled
    res["agent_rss"] = agents
    return res


def machine() -> dict:
    model = next(
        (ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")),
        platform.processor(),
    )
    commit = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()

    def v(dist: str) -> str | None:
        try:
            return version(dist)
        except PackageNotFoundError:
            return None

    return {
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "cpu": model,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "versions": {d: v(d) for d in ("eclipse-zenoh", "pyzmq", "cyclonedds", "dora-rs", "dora-rs-cli")},
    }


def fmt(v: float | None, spec: str = ".0f") -> str:
    return "-" if v is None else format(v, spec)


def med(runs: list[dict], key: str) -> float | None:
    vals = [r[key] for r in runs if r.get("ok") and r.get(key) is not None]
    return statistics.median(vals) if vals else None


def table(results: dict) -> str:
    m = results["machine"]
    loads = [r["load1"] for r in results["runs"] if "load1" in r]
    lines = [
        f"{m['date']}, commit {m['commit']}, {m['cpu']}, {m['cores']} cores, Python {m['python']}; "
        + ", ".join(f"{k} {v}" for k, v in m["versions"].items() if v),
        f"{results['reps']} interleaved repetitions, {results['ticks']} measured ticks after "
        f"{results['warmup']} warm-up; load average (1 min) before the runs "
        f"{fmt(min(loads), '.2f') if loads else '-'}-{fmt(max(loads), '.2f') if loads else '-'}",
        "",
        "| N | K | system | ticks/s (each repetition) | median | vs bare zenoh | tick p50 / p99 ms | "
        "CPU ms / tick | RSS MB (sum) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for size in results["sizes"]:
        runs = [r for r in results["runs"] if r["size"] == size["name"]]
        floor = med([r for r in runs if r["system"] == "zenoh"], "ticks_per_second")
        for system in results["systems"]:
            rs = [r for r in runs if r["system"] == system]
            if not rs:
                continue
            each = " / ".join(fmt(r.get("ticks_per_second")) if r.get("ok") else "failed" for r in rs)
            tps = med(rs, "ticks_per_second")
            k = size["k_label"]
            if system == "swarm" and med(rs, "contacts") is not None:
                k = f"{med(rs, 'contacts'):.1f} sensed"
            lines.append(
                f"| {size['n']} | {k} | {LABELS[system]} | {each} | {fmt(tps)} | "
                f"{fmt(tps / floor, '.2f') if tps and floor else '-'} | "
                f"{fmt(med(rs, 'tick_ms_p50'), '.2f')} / {fmt(med(rs, 'tick_ms_p99'), '.2f')} | "
                f"{fmt(med(rs, 'cpu_ms_per_tick'), '.2f')} | {fmt(med(rs, 'rss_mb'))} |"
            )
    for system, why in results["skipped"].items():
        lines.append(f"\n{LABELS.get(system, system)}: not run: {why}")
    for r in results["runs"]:
        if not r.get("ok"):
            lines.append(f"\n{LABELS[r['system']]} N={r['n']} failed: {r.get('error', '?')}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", default="6,20,50", help="sizes with unlimited sensing (K = N - 1)")
    ap.add_argument("--range-n", type=int, default=100, help="a size with a sensing range (0: none)")
    ap.add_argument("--range-k", type=int, default=8, help="about this many in sight at --range-n")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=2000, help="measured ticks per run")
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--systems", default=",".join(SYSTEMS))
    ap.add_argument(
        "--dora-max-n",
        type=int,
        default=50,
        help="run dora-rs up to this N (default 50: at N = 100 its nodes' zenoh sessions, which scout "
        "each other, took a 2-core machine to a load of 300 and nodes failed to start)",
    )
    ap.add_argument("--smoke", action="store_true", help="N = 3, 50 ticks, zenoh + zmq + swarm up, once")
    ap.add_argument("--json", type=Path, help="write every run to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the work directory")
    a = ap.parse_args(argv)
    if a.smoke:
        a.n, a.range_n, a.reps, a.ticks, a.warmup, a.systems = "3", 0, 1, 50, 20, "zenoh,zmq,swarm"
    systems = [s for s in a.systems.split(",") if s]
    unknown = set(systems) - set(SYSTEMS)
    if unknown:
        ap.error(f"unknown systems {sorted(unknown)}; known: {', '.join(SYSTEMS)}")
    skipped = {s: why for s in systems if (why := missing(s))}
    systems = [s for s in systems if s not in skipped]
    sizes: list[dict] = [
        {"name": f"{n}", "n": int(n), "k": int(n) - 1, "range": False, "k_label": f"{int(n) - 1} (all)"}
        for n in a.n.split(",")
        if n
    ]
    if a.range_n:
        sizes.append(
            {"name": f"{a.range_n}r", "n": a.range_n, "k": a.range_k, "range": True, "k_label": f"~{a.range_k} (range)"}
        )
    results: dict = {
        "machine": machine(),
        "reps": a.reps,
        "ticks": a.ticks,
        "warmup": a.warmup,
        "dt": DT,
        "sizes": sizes,
        "systems": systems,
        "skipped": skipped,
        "runs": [],
    }
    for s, why in skipped.items():
        log(f"{s}: not run: {why}")
    rt = tempfile.mkdtemp(prefix="pr", dir="/tmp")  # short: Unix socket paths are limited to 108 bytes
    work = Path(tempfile.mkdtemp(prefix="swarm-peers-"))
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt, "PYTHONUNBUFFERED": "1"}
    log(f"work dir {work}")
    try:
        for rep in range(a.reps):
            for size in sizes:
                order = systems[rep % len(systems) :] + systems[: rep % len(systems)]
                for system in order:
                    if system == "dora" and size["n"] > a.dora_max_n:
                        results["skipped"][f"dora at N = {size['n']}"] = f"above --dora-max-n {a.dora_max_n}"
                        continue
                    tag = f"{size['name']}-{rep}"
                    log(
                        f"[rep {rep + 1}/{a.reps}] N={size['n']} K={size['k']} {system} (load {os.getloadavg()[0]:.2f})"
                    )
                    if system == "swarm":
                        r = run_up(size["n"], size["k"] if size["range"] else None, a.ticks, a.warmup, work, env, tag)
                    else:
                        r = run_peer(system, size["n"], size["k"], a.ticks, a.warmup, work, env, tag)
                    r.update(size=size["name"], rep=rep)
                    results["runs"].append(r)
                    log(
                        f"  -> {fmt(r.get('ticks_per_second'))} ticks/s, "
                        f"{fmt(r.get('cpu_ms_per_tick'), '.2f')} ms CPU/tick {r.get('error', '')}"
                    )
    finally:
        if a.keep:
            log(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(rt, ignore_errors=True)
    print(table(results))
    if a.json:
        a.json.write_text(json.dumps(results, indent=2) + "\n")
    return ExitCode.OK if all(r.get("ok") for r in results["runs"]) else ExitCode.FAILED


if __name__ == "__main__":
    sys.exit(main())
