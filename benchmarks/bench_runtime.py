"""Runtime figures of `swarm up` against a bare-zenoh lockstep floor (a benchmark, not a test).

    python benchmarks/bench_runtime.py [--quick] [--json FILE] [--sizes 6,20,50]
                                       [--repeat R] [--profile] [--keep]

Measured in one run, on this machine:

1. Bare-zenoh lockstep baseline for each N: benchmarks/bare_hub.py (router mode, swarm's
   own hub_config) and N benchmarks/bare_client.py processes (client_config); per tick
   the hub sends one small message to each client on its own key and waits for every
   client's answer. No physics, no law. ticks/s over a fixed tick count after a warm-up.
2. Lockstep ticks/s of `swarm up` for the same N on a generated scenario (1-2 leaders,
   the rest followers with selection = "nearest", on a ring; speeds and radii like
   scenarios/case2.toml), read from summary.json (`ticks_per_second`).
3. For the largest N: the time from Popen of `swarm up` to the first tick (the start
   event's wall_time minus the Popen time) and the world's own startup_s.
4. Resident memory of every agent process during each swarm run (psutil): RSS sampled
   about once a second while ticking, USS (memory_full_info().uss) once while ticking.
   RSS counts shared pages (libpython, the zenoh .so, numpy) in every process; USS is
   what each process adds on its own.

The machine is shared and has 2 cores: baseline and swarm runs of one N are interleaved,
--repeat R repeats each pair and the table uses the best (least disturbed) run of each;
the 1-minute load average before each run is in the JSON. --profile adds a separate
(unmeasured) 20-agent run with py-spy attached to the world, one follower agent, one
leader agent and the launcher while ticking, and prints their hottest functions.

Every process is started here (own process group; `swarm up` starts its world and
agents in a group of its own, which is found through psutil and swept at the end), every
wait has a deadline, Unix sockets live in a private short directory given to every child
as SWARM_RUNTIME_DIR, and only processes started here are ever signalled.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parents[1]
BENCH = Path(__file__).resolve().parent
PY = sys.executable
DT = 0.01
MB = 1024 * 1024

TARGET_RATIO = 0.8  # swarm ticks/s >= 0.8 x bare baseline
TARGET_FIRST_TICK_S = 5.0  # Popen -> first tick for the largest N
TARGET_AGENT_MB = 40.0  # resident memory per agent process

# Baseline ticks measured (after the warm-up) per N; --quick divides by 4.
BASE_TICKS = {6: 6000, 20: 2000, 50: 800}


def base_ticks(n: int, quick: bool) -> tuple[int, int]:
    ticks = BASE_TICKS.get(n) or max(200, int(40000 / n))
    if quick:
        ticks = max(150, ticks // 4)
    return ticks, max(50, ticks // 10)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# -- processes -----------------------------------------------------------------------------------
class Tracked:
    """Everything one measurement started: its own Popens and the descendants seen of them."""

    def __init__(self):
        self.popens: list[subprocess.Popen] = []
        self.seen: dict[int, psutil.Process] = {}  # pid -> Process (create_time pins identity)
        self.pgid: int | None = None

    def spawn(self, args: list[str], logfile: Path, env: dict, own_group: bool = True) -> subprocess.Popen:
        with open(logfile, "ab") as out:
            p = subprocess.Popen(args, cwd=REPO, env=env, stdin=subprocess.DEVNULL, stdout=out,
                                 stderr=subprocess.STDOUT,
                                 process_group=0 if (own_group or self.pgid is None) else self.pgid)
        if self.pgid is None:
            self.pgid = p.pid
        self.popens.append(p)
        try:
            self.seen[p.pid] = psutil.Process(p.pid)
        except psutil.NoSuchProcess:
            pass
        return p

    def discover(self, parent: subprocess.Popen) -> list[psutil.Process]:
        """Current descendants of one of our Popens (remembered for the final sweep)."""
        try:
            kids = self.seen[parent.pid].children(recursive=True)
        except (psutil.NoSuchProcess, KeyError):
            return []
        for k in kids:
            self.seen.setdefault(k.pid, k)
        return kids

    def alive(self) -> list[psutil.Process]:
        out = []
        for pr in self.seen.values():
            try:
                if pr.is_running() and pr.status() != psutil.STATUS_ZOMBIE:
                    out.append(pr)
            except psutil.NoSuchProcess:
                pass
        return out

    def stop(self, grace: float = 15.0) -> None:
        """SIGTERM our Popens (swarm up stops its own world and agents), then SIGKILL what is left."""
        for p in self.popens:
            if p.poll() is None:
                self.discover(p)
                try:
                    p.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
        t_end = time.monotonic() + grace
        while time.monotonic() < t_end and any(p.poll() is None for p in self.popens):
            time.sleep(0.05)
        for p in self.popens:
            self.discover(p)
        for pr in self.alive():
            try:
                pr.kill()
            except psutil.NoSuchProcess:
                pass
        psutil.wait_procs(self.alive(), timeout=5)
        for p in self.popens:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                log(f"warning: process {p.pid} did not exit after SIGKILL")


def wait_all(procs: list[subprocess.Popen], deadline: float, tick=None) -> bool:
    """Wait until every process exited or the monotonic deadline; `tick()` runs every 0.25 s."""
    while time.monotonic() < deadline:
        if all(p.poll() is not None for p in procs):
            return True
        if tick is not None:
            tick()
        time.sleep(0.25)
    return all(p.poll() is not None for p in procs)


class MemSampler:
    """RSS of a set of processes about once a second; USS once, when asked."""

    def __init__(self):
        self.rss: dict[int, float] = {}  # pid -> peak RSS seen (MB)
        self.uss: dict[int, float] = {}  # pid -> USS (MB), one sample
        self.last = 0.0

    def sample_rss(self, procs: list[psutil.Process], every: float = 1.0) -> None:
        now = time.monotonic()
        if now - self.last < every:
            return
        self.last = now
        for pr in procs:
            try:
                mb = pr.memory_info().rss / MB
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                continue
            self.rss[pr.pid] = max(self.rss.get(pr.pid, 0.0), mb)

    def sample_uss(self, procs: list[psutil.Process]) -> None:
        for pr in procs:
            try:
                self.uss[pr.pid] = pr.memory_full_info().uss / MB
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                continue

    def stats(self) -> dict:
        def s(d):
            v = list(d.values())
            return {"n": len(v), "mean_mb": statistics.fmean(v), "max_mb": max(v)} if v else None
        return {"rss": s(self.rss), "uss": s(self.uss)}


def is_agent(pr: psutil.Process) -> bool:
    try:
        return "agents.process" in pr.cmdline()
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return False


def is_world(pr: psutil.Process) -> bool:
    try:
        c = pr.cmdline()
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return False
    return "swarm" in c and "world" in c


# -- 1. bare baseline ------------------------------------------------------------------------------
def run_baseline(n: int, ticks: int, warmup: int, work: Path, env: dict, tag: str) -> dict:
    d = work / f"bare-{tag}"
    d.mkdir()
    endpoint = f"unixsock-stream/{env['SWARM_RUNTIME_DIR']}/b{tag}.sock"
    result = d / "result.json"
    run = f"b{tag}"
    tr = Tracked()
    mem = MemSampler()
    load = os.getloadavg()[0]
    try:
        hub = tr.spawn([PY, str(BENCH / "bare_hub.py"), "--listen", endpoint, "--run", run, "--n", str(n),
                        "--ticks", str(ticks), "--warmup", str(warmup), "--result", str(result),
                        "--join-timeout", "90"], d / "hub.log", env)
        clients = [tr.spawn([PY, str(BENCH / "bare_client.py"), str(i), endpoint, run, "--timeout", "240"],
                            d / f"client-{i}.log", env, own_group=False) for i in range(n)]
        cps = [tr.seen[c.pid] for c in clients if c.pid in tr.seen]
        t0 = time.monotonic()
        state = {"uss": False}

        def sample():
            mem.sample_rss(cps)
            # USS once, when the clients have been up for a while (the hub is ticking or about to).
            if not state["uss"] and time.monotonic() - t0 > 3.0 + 0.15 * n:
                state["uss"] = True
                mem.sample_uss(cps)

        wait_all([hub], time.monotonic() + 120 + ticks / 20, sample)
        wait_all(clients, time.monotonic() + 10)
    finally:
        tr.stop()
    if not result.exists():
        return {"n": n, "ok": False, "error": f"hub wrote no result; see {d / 'hub.log'}", "load1": load}
    r = json.loads(result.read_text())
    r.update(load1=load, memory=mem.stats())
    return r


# -- 2-4. swarm up ---------------------------------------------------------------------------------
FOLLOWER_SPEEDS = [35.0, 50.0, 18.0, 22.0, 30.0, 45.0, 25.0, 40.0]  # m/s, case2's and more like them
LEADERS = [(28.0, 28.0), (40.0, 40.0)]  # (speed m/s, orbit radius m): omega = v / R = 1 rad/s


def scenario_toml(n: int) -> str:
    """n agents on a 30 m ring around the target: 1-2 leaders, the rest nearest-selection followers."""
    rng = random.Random(n)
    n_leaders = 1 if n < 4 else 2
    leader_slots = {0: 0} if n_leaders == 1 else {0: 0, n // 2: 1}
    lines = [f'name = "bench-{n}"',
             f'description = "benchmarks/bench_runtime.py: {n} agents on a ring, {n_leaders} leader(s)"',
             "", "[run]", f"dt = {DT}", "duration = 60.0", 'clock = "lockstep"', "seed = 1",
             "", "[target]", "x = 0.0", "y = 0.0",
             "", "[gains]", "c1 = 1.0", "c2 = 0.5",
             "", "[sensing]", 'selection = "nearest"', ""]
    f = 0
    for k in range(n):
        ang = 2 * math.pi * k / n
        x, y = 30.0 * math.cos(ang), 30.0 * math.sin(ang)
        heading = math.atan2(math.sin(ang + math.pi / 2 + rng.uniform(-0.5, 0.5)),
                             math.cos(ang + math.pi / 2 + rng.uniform(-0.5, 0.5)))
        lines += ["[[agents]]", f"id = {k + 1}"]
        if k in leader_slots:
            v, r = LEADERS[leader_slots[k]]
            lines += ['role = "leader"', f"x = {x:.4f}", f"y = {y:.4f}", f"heading = {heading:.4f}",
                      f"speed = {v}", f"orbit_radius = {r}", 'direction = "ccw"', ""]
        else:
            v = FOLLOWER_SPEEDS[f % len(FOLLOWER_SPEEDS)]
            f += 1
            lines += ['role = "follower"', f"x = {x:.4f}", f"y = {y:.4f}", f"heading = {heading:.4f}",
                      f"speed = {v}", ""]
    return "\n".join(lines)


def world_started(out: Path) -> bool:
    try:
        return "start agent None" in (out / "logs" / "world.log").read_text(errors="replace")
    except OSError:
        return False


def run_swarm(n: int, ticks: int, work: Path, env: dict, tag: str, profile: float = 0.0) -> dict:
    """One `swarm up`; profile > 0: attach py-spy for that many seconds once ticking."""
    d = work / f"up-{tag}"
    d.mkdir()
    toml = d / f"bench{n}.toml"
    toml.write_text(scenario_toml(n))
    out = d / "out"
    tr = Tracked()
    mem, wmem = MemSampler(), MemSampler()
    load = os.getloadavg()[0]
    spies: list[tuple[str, int, subprocess.Popen, Path]] = []
    state = {"started": None, "uss": False, "agents": [], "world": None, "last_discover": 0.0}
    try:
        t_popen = time.time()
        up = tr.spawn([PY, "-m", "swarm", "up", str(toml), "--out", str(out), "--duration", f"{ticks * DT:.6f}",
                       "--no-plots"], d / "up.log", env)

        def sample():
            now = time.monotonic()
            if now - state["last_discover"] > 1.0 and (state["started"] is None or not state["agents"]):
                state["last_discover"] = now
                kids = tr.discover(up)
                state["agents"] = [k for k in kids if is_agent(k)]
                ws = [k for k in kids if is_world(k)]
                state["world"] = ws[0] if ws else None
            if state["started"] is None:
                if world_started(out):
                    state["started"] = now
                    state["last_discover"] = 0.0
                return
            mem.sample_rss(state["agents"])
            if state["world"] is not None:
                wmem.sample_rss([state["world"]])
            if not state["uss"] and now - state["started"] > 1.0:
                state["uss"] = True
                mem.sample_uss(state["agents"])
                if state["world"] is not None:
                    wmem.sample_uss([state["world"]])
                if profile > 0:
                    start_spies()

        def start_spies():
            pyspy = shutil.which("py-spy", path=str(Path(PY).parent)) or shutil.which("py-spy")
            if pyspy is None:
                log("py-spy not found: pip install py-spy into the venv for --profile")
                return
            followers = [a for a in state["agents"] if a.cmdline()[-3] != "1" and a.cmdline()[-3] != str(n // 2 + 1)]
            leaders = [a for a in state["agents"] if a.cmdline()[-3] == "1"]
            targets = [("world", state["world"]), ("launcher", tr.seen.get(up.pid)),
                       ("follower agent", followers[len(followers) // 2] if followers else None),
                       ("leader agent", leaders[0] if leaders else None)]
            for name, pr in targets:
                if pr is None:
                    continue
                raw = d / f"pyspy-{name.replace(' ', '-')}.txt"
                p = tr.spawn([pyspy, "record", "-p", str(pr.pid), "-d", f"{profile:g}", "-r", "100", "-f", "raw",
                              "--nolineno", "--threads", "--nonblocking", "-o", str(raw)],
                             d / f"pyspy-{name.replace(' ', '-')}.log", env)
                spies.append((name, pr.pid, p, raw))

        finished = wait_all([up], time.monotonic() + 120 + ticks / 20, sample)
        if not finished:
            log(f"swarm up ({n} agents) passed its deadline; stopping it")
        wait_all([s[2] for s in spies], time.monotonic() + profile + 15)
    finally:
        tr.stop()
    res: dict = {"n": n, "ticks_requested": ticks, "load1": load, "ok": False,
                 "memory_agents": mem.stats(), "memory_world": wmem.stats()}
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError) as e:
        res["error"] = f"no summary.json ({e}); see {d}"
        return res
    start = next((e for e in summary.get("events", []) if e.get("kind") == "start"), None)
    agents = summary.get("agents", {})
    res.update(
        ok=bool(summary.get("completed")) and summary.get("ticks_per_second") is not None,
        completed=summary.get("completed"), ticks=summary.get("ticks"),
        ticks_per_second=summary.get("ticks_per_second"), wall_time=summary.get("wall_time"),
        startup_s=start.get("startup_s") if start else None,
        first_tick_s=(start["wall_time"] - t_popen) if start else None,
        missed_ticks=sum(int(a.get("missed_ticks", 0)) for a in agents.values()),
        drops=sum(int(a.get("drops", 0)) for a in agents.values()),
        agent_pids=sorted(int(a["pid"]) for a in agents.values() if a.get("pid")),
    )
    if spies:
        res["profile"] = {name: summarize_pyspy(raw, profile) for name, _pid, _p, raw in spies}
    return res


# -- py-spy -----------------------------------------------------------------------------------
def summarize_pyspy(raw: Path, seconds: float, rate: int = 100, top: int = 10) -> dict:
    """Per Python thread: busy share, hottest functions by self and by inclusive samples."""
    try:
        text = raw.read_text()
    except OSError:
        return {"error": f"no py-spy output {raw}"}
    threads: dict[str, dict] = defaultdict(lambda: {"samples": 0, "self": Counter(), "incl": Counter()})
    for line in text.splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        c = int(count)
        frames = stack.split(";")
        th = frames[0] if frames[0].startswith(("thread", "process")) else "main"
        frames = [f for f in frames if not f.startswith(("thread", "process"))]
        if not frames:
            continue
        t = threads[th]
        t["samples"] += c
        t["self"][frames[-1]] += c
        for f in set(frames):
            t["incl"][f] += c
    expected = seconds * rate
    out = {}
    for th, t in sorted(threads.items(), key=lambda kv: -kv[1]["samples"]):
        n = t["samples"]
        out[th] = {"busy_share": n / expected, "samples": n,
                   "self": [(f, c / n) for f, c in t["self"].most_common(top)],
                   "inclusive": [(f, c / n) for f, c in t["incl"].most_common(top)]}
    return out


# -- report -----------------------------------------------------------------------------------------
def best(runs: list[dict], key: str = "ticks_per_second") -> dict | None:
    ok = [r for r in runs if r.get("ok") and r.get(key)]
    return max(ok, key=lambda r: r[key]) if ok else None


def fmt(v, spec=".0f", none="-"):
    return none if v is None else format(v, spec)


def report(results: dict) -> str:
    lines = []
    lines.append(f"machine: {results['env']['cpus']} CPUs, python {results['env']['python']}, "
                 f"zenoh {results['env']['zenoh']}; mode {'quick' if results['quick'] else 'full'}, "
                 f"repeat {results['repeat']} (best run shown)")
    lines.append("")
    lines.append(f"{'N':>3} | {'baseline ticks/s':>16} | {'swarm ticks/s':>13} | {'ratio':>5} | "
                 f"target (>= {TARGET_RATIO}x) met? | runs baseline / swarm (load1)")
    lines.append("-" * 110)
    for n in results["sizes"]:
        r = results["by_n"][str(n)]
        b, s = best(r["baseline"]), best(r["swarm"])
        ratio = (s["ticks_per_second"] / b["ticks_per_second"]) if (b and s) else None
        r["ratio"] = ratio
        met = None if ratio is None else ratio >= TARGET_RATIO
        runs = (", ".join(f"{fmt(x.get('ticks_per_second'))}({x['load1']:.1f})" for x in r["baseline"]) + " / "
                + ", ".join(f"{fmt(x.get('ticks_per_second'))}({x['load1']:.1f})" for x in r["swarm"]))
        lines.append(f"{n:>3} | {fmt(b and b['ticks_per_second']):>16} | {fmt(s and s['ticks_per_second']):>13} | "
                     f"{fmt(ratio, '.2f'):>5} | {('yes' if met else 'NO') if met is not None else '-':>24} | {runs}")
    lines.append("")
    big = str(max(results["sizes"]))
    sw = [x for x in results["by_n"][big]["swarm"] if x.get("first_tick_s") is not None]
    if sw:
        ft = min(x["first_tick_s"] for x in sw)
        su = min(x["startup_s"] for x in sw)
        lines.append(f"first tick, {big} agents: {ft:.2f} s from Popen of `swarm up` (world startup_s {su:.2f} s; "
                     f"runs: {', '.join(format(x['first_tick_s'], '.2f') for x in sw)}) vs target "
                     f"{TARGET_FIRST_TICK_S:.0f} s: {'met' if ft <= TARGET_FIRST_TICK_S else 'NOT met'}")
    else:
        lines.append(f"first tick, {big} agents: no successful run")
    lines.append("")
    lines.append(f"memory per agent process (target {TARGET_AGENT_MB:.0f} MB); RSS = peak of ~1 s samples while "
                 "ticking, USS = one sample while ticking")
    lines.append(f"{'N':>3} | {'agents':>6} | {'RSS mean':>8} | {'RSS max':>7} | {'USS mean':>8} | {'USS max':>7} | "
                 f"{'met (RSS max / USS max)':>24} | bare client RSS mean / USS mean | world RSS / USS")
    lines.append("-" * 130)
    for n in results["sizes"]:
        r = results["by_n"][str(n)]
        s = next((x for x in r["swarm"] if (x.get("memory_agents") or {}).get("rss")), None)
        b = next((x for x in r["baseline"] if (x.get("memory") or {}).get("rss")), None)
        if s is None:
            lines.append(f"{n:>3} | no samples")
            continue
        ma, mw = s["memory_agents"], s["memory_world"]
        rss, uss = ma["rss"], ma["uss"] or {}
        met = (f"{'yes' if rss['max_mb'] <= TARGET_AGENT_MB else 'NO'} / "
               f"{('yes' if uss['max_mb'] <= TARGET_AGENT_MB else 'NO') if uss else '-'}")
        bare = (f"{b['memory']['rss']['mean_mb']:.1f} / {fmt((b['memory']['uss'] or {}).get('mean_mb'), '.1f')}"
                if b else "-")
        world = (f"{fmt((mw['rss'] or {}).get('max_mb'), '.1f')} / {fmt((mw['uss'] or {}).get('max_mb'), '.1f')}")
        lines.append(f"{n:>3} | {rss['n']:>6} | {rss['mean_mb']:8.1f} | {rss['max_mb']:7.1f} | "
                     f"{fmt(uss.get('mean_mb'), '8.1f'):>8} | {fmt(uss.get('max_mb'), '7.1f'):>7} | {met:>24} | "
                     f"{bare:>31} | {world}")
    prof = results.get("profile")
    if prof:
        lines.append("")
        lines.append(f"py-spy, {prof['n']} agents, {prof['seconds']:g} s while ticking "
                     f"(run at {fmt(prof.get('ticks_per_second'))} ticks/s; share of samples; "
                     "busy = share of wall time the thread ran Python)")
        for proc, threads in (prof.get("profile") or {}).items():
            if "error" in threads:
                lines.append(f"  {proc}: {threads['error']}")
                continue
            for th, t in list(threads.items())[:3]:
                lines.append(f"  {proc} [{th}] busy {100 * t['busy_share']:.0f}%")
                lines.append("    self:      " + "; ".join(f"{f} {100 * c:.0f}%" for f, c in t["self"][:6]))
                lines.append("    inclusive: " + "; ".join(f"{f} {100 * c:.0f}%" for f, c in t["inclusive"][:8]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="swarm up vs bare zenoh: lockstep ticks/s, first tick, memory")
    ap.add_argument("--quick", action="store_true", help="fewer ticks (about a quarter)")
    ap.add_argument("--sizes", default="6,20,50", help="agent counts, comma-separated (default 6,20,50)")
    ap.add_argument("--repeat", type=int, default=None, help="runs of each pair (default 2, quick 1)")
    ap.add_argument("--swarm-seconds", type=float, default=None,
                    help="aim for this many s of ticking per swarm run (default 4, quick 1.5)")
    ap.add_argument("--profile", action="store_true", help="also profile a 20-agent run with py-spy")
    ap.add_argument("--json", type=Path, help="write all results to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the work directory (logs, runs)")
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.sizes.split(",") if x.strip()]
    repeat = a.repeat or (1 if a.quick else 2)
    secs = a.swarm_seconds or (1.5 if a.quick else 4.0)

    import zenoh

    rt = tempfile.mkdtemp(prefix="sw", dir="/tmp")  # short: Unix socket paths are limited to 108 bytes
    work = Path(tempfile.mkdtemp(prefix="swarm-bench-"))
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt, "PYTHONUNBUFFERED": "1"}
    results: dict = {
        "quick": a.quick, "repeat": repeat, "sizes": sizes, "swarm_seconds": secs,
        "env": {"cpus": os.cpu_count(), "python": platform.python_version(),
                "zenoh": getattr(zenoh, "__version__", None) or _dist_version("eclipse-zenoh"),
                "platform": platform.platform()},
        "targets": {"ratio": TARGET_RATIO, "first_tick_s": TARGET_FIRST_TICK_S, "agent_mb": TARGET_AGENT_MB},
        "by_n": {},
    }
    log(f"work dir {work}, runtime dir {rt}")
    try:
        for n in sizes:
            ticks, warmup = base_ticks(n, a.quick)
            r = results["by_n"][str(n)] = {"baseline": [], "swarm": []}
            for k in range(repeat):
                log(f"[N={n} run {k + 1}/{repeat}] bare baseline: {ticks} ticks after {warmup} warm-up")
                b = run_baseline(n, ticks, warmup, work, env, f"{n}-{k}")
                r["baseline"].append(b)
                log(f"  -> {fmt(b.get('ticks_per_second'))} ticks/s {b.get('error', '')}")
                tps = b.get("ticks_per_second") or {6: 3500, 20: 990, 50: 350}.get(n, 20000 / n)
                sticks = int(min(40000, max(300, 0.8 * tps * secs)))
                log(f"[N={n} run {k + 1}/{repeat}] swarm up: {sticks} ticks")
                s = run_swarm(n, sticks, work, env, f"{n}-{k}")
                r["swarm"].append(s)
                log(f"  -> {fmt(s.get('ticks_per_second'))} ticks/s, first tick {fmt(s.get('first_tick_s'), '.2f')} s"
                    f" {s.get('error', '')}")
        if a.profile:
            n = 20
            b = best(results["by_n"].get(str(n), {}).get("baseline", [])) if str(n) in results["by_n"] else None
            tps = (b or {}).get("ticks_per_second") or 990
            seconds = 4.0
            sticks = int(0.8 * tps * (seconds + 4.0))
            log(f"[profile] swarm up, {n} agents, {sticks} ticks, py-spy for {seconds:g} s")
            p = run_swarm(n, sticks, work, env, f"profile-{n}", profile=seconds)
            results["profile"] = {"n": n, "seconds": seconds, "ticks_per_second": p.get("ticks_per_second"),
                                  "profile": p.get("profile")}
    finally:
        if a.keep:
            log(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(rt, ignore_errors=True)
    text = report(results)
    print(text)
    if a.json:
        a.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


def _dist_version(name: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return None


if __name__ == "__main__":
    sys.exit(main())
