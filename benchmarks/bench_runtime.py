"""Runtime figures of `swarm up` against a bare-zenoh lockstep floor (a benchmark, not a test).

    python benchmarks/bench_runtime.py [--quick] [--json FILE] [--sizes 6,20,50] [--repeat R]
                                       [--quiet-wait S] [--swarm-seconds S] [--profile] [--keep]

Measured in one run, on this machine:

1. Bare-zenoh lockstep baseline for each N: benchmarks/bare_hub.py (router mode, swarm's
   own hub_config) and N benchmarks/bare_client.py processes (client_config); per tick
   the hub sends one small message to each client on its own key and waits for every
   client's answer, which the client sends from its zenoh callback, as agents do
   (--floor-handler callback: from its main thread after a queue). No physics, no law.
   ticks/s over a fixed tick count after a warm-up. With --neighbours K the scenario
   gets a sensing range under which each agent senses about K others at the start.
2. Lockstep ticks/s of `swarm up` for the same N on a generated scenario (1-2 leaders,
   the rest followers with selection = "nearest", on a ring; speeds and radii like
   scenarios/case2.toml), read from summary.json (`ticks_per_second`; the world's own
   p50/p99/max of a tick's wall time, `tick_ms`, as tick_ms_p50 / _p99 / _max in the JSON).
3. For the largest N: the time from Popen of `swarm up` to the first tick (the start
   event's wall_time minus the Popen time) and the world's own startup_s.
4. Resident memory of every agent process during each swarm run (psutil): RSS sampled
   about once a second while ticking, USS (memory_full_info().uss) once while ticking.
   RSS counts shared pages (libpython, the zenoh .so, numpy) in every process; USS is
   what each process adds on its own.

Also printed: CPU per tick of each kind of process while ticking (psutil cpu_times), and
how busy the machine was with processes not started here. The machine is shared and has
2 cores: before each run the benchmark waits (up to --quiet-wait s) for the machine to
quieten, baseline and swarm runs of one N are interleaved, --repeat R repeats each pair
and the table uses the best (least disturbed) run of each; every run is in the JSON.
--profile adds a separate (unmeasured) 20-agent run (--profile-n): CPU per thread of the world, one
follower agent, one leader agent and the launcher, then py-spy attached to each of them.

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
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from collections import Counter, defaultdict
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
import psutil
import zenoh

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # the repository's swarm, not an installed copy

from swarm.contracts import credentials  # noqa: E402
from swarm.contracts.scenario import parse_scenario  # noqa: E402
from swarm.contracts.vocabulary import EventKind, ExitCode  # noqa: E402
from swarm.offline.batch import run_batch  # noqa: E402
from swarm.runtime.procs import Group, agent_id_of, stop_groups, wait_until  # noqa: E402

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
    """Everything one measurement started: its process groups (swarm.runtime.procs) and the descendants
    seen of them."""

    def __init__(self):
        self.groups: list[Group] = []
        self.seen: dict[int, psutil.Process] = {}  # pid -> Process (create_time pins identity)

    @property
    def popens(self) -> list[subprocess.Popen]:
        return [p for g in self.groups for p in g.members]

    def spawn(self, args: list[str], logfile: Path, env: dict, own_group: bool = True) -> subprocess.Popen:
        """Start `args` in a process group of its own, or (own_group=False) in the first one started."""
        if own_group or not self.groups:
            self.groups.append(Group())
        group = self.groups[-1] if own_group else self.groups[0]
        with open(logfile, "ab") as out:
            p = group.start(args, cwd=REPO, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
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
        """SIGTERM our groups (swarm up stops its own world and agents), SIGKILL them if still
        running `grace` s later, then SIGKILL every descendant seen that is left."""
        for p in self.popens:
            if p.poll() is None:
                self.discover(p)
        stop_groups(self.groups, grace)
        for pr in self.alive():
            try:
                pr.kill()
            except psutil.NoSuchProcess:
                pass
        psutil.wait_procs(self.alive(), timeout=5)
        for p in self.popens:
            if p.returncode is None:
                log(f"warning: process {p.pid} did not exit after SIGKILL")


def all_exited(procs: list[subprocess.Popen], tick=None) -> Callable[[], bool]:
    """A condition for wait_until: every process exited; until then `tick()` runs at each look."""

    def cond() -> bool:
        if all(p.poll() is not None for p in procs):
            return True
        if tick is not None:
            tick()
        return False

    return cond


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


class CpuMeter:
    """CPU seconds (user + system) of named groups of processes between samples, and of the machine."""

    def __init__(self):
        self.samples: list[tuple[float, float, dict]] = []  # (monotonic, machine busy s, {(group, pid): s})
        self.last = 0.0

    def sample(self, groups: dict[str, list[psutil.Process]], every: float = 0.5) -> None:
        now = time.monotonic()
        if now - self.last < every:
            return
        self.last = now
        ct = psutil.cpu_times()
        busy = sum(ct) - ct.idle - getattr(ct, "iowait", 0.0)
        vals = {}
        for g, procs in groups.items():
            for pr in procs:
                try:
                    t = pr.cpu_times()
                except (psutil.NoSuchProcess, psutil.AccessDenied):
                    continue
                vals[(g, pr.pid)] = t.user + t.system
        self.samples.append((now, busy, vals))

    def result(self, drop_last: bool = False) -> dict | None:
        """Cores used per group and by the machine between the first and the last (kept) sample."""
        smp = self.samples[:-1] if drop_last and len(self.samples) >= 3 else self.samples
        if len(smp) < 2:
            return None
        (t0, b0, v0), (t1, b1, v1) = smp[0], smp[-1]
        dt = t1 - t0
        cpu: dict[str, float] = defaultdict(float)
        for k, v in v1.items():
            if k in v0:
                cpu[k[0]] += v - v0[k]
        ours = sum(cpu.values())
        return {
            "window_s": dt,
            "cpu_s": dict(cpu),
            "machine_busy_cores": (b1 - b0) / dt,
            "ours_cores": ours / dt,
            "others_cores": max(0.0, (b1 - b0) - ours) / dt,
        }


def cpu_so_far(procs: list[psutil.Process]) -> list[float]:
    """CPU seconds (user + system) each process used since it started."""
    out = []
    for pr in procs:
        try:
            t = pr.cpu_times()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        out.append(t.user + t.system)
    return out


def startup_cpu(agents: list[psutil.Process], others: dict[str, psutil.Process | None]) -> dict:
    a = cpu_so_far(agents)
    res = {"agents_n": len(a), "agents_mean_s": statistics.fmean(a) if a else None, "agents_sum_s": sum(a)}
    for name, pr in others.items():
        c = cpu_so_far([pr]) if pr is not None else []
        res[f"{name}_s"] = c[0] if c else None
    return res


def is_agent(pr: psutil.Process) -> bool:
    try:
        return agent_id_of(pr.cmdline()) is not None
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return False


def is_world(pr: psutil.Process) -> bool:
    try:
        c = pr.cmdline()
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return False
    return "swarm" in c and "world" in c


def wait_quiet(threshold: float, max_wait: float) -> dict:
    """Wait (at most max_wait s) until the machine's busy cores over 1 s drop below threshold."""
    t0 = time.monotonic()
    busy = None
    while True:
        c0 = psutil.cpu_times()
        time.sleep(1.0)
        c1 = psutil.cpu_times()
        b = [sum(c) - c.idle - getattr(c, "iowait", 0.0) for c in (c0, c1)]
        busy = b[1] - b[0]
        if busy < threshold or time.monotonic() - t0 >= max_wait:
            return {"waited_s": time.monotonic() - t0, "busy_cores": busy}


# -- 1. bare baseline ------------------------------------------------------------------------------
def run_baseline(n: int, ticks: int, warmup: int, work: Path, env: dict, tag: str, auth: bool = False) -> dict:
    """The bare lockstep floor; with `auth`, the hub checks every client as a world does."""
    d = work / f"bare-{tag}"
    d.mkdir()
    endpoint = f"unixsock-stream/{env['SWARM_RUNTIME_DIR']}/b{tag}.sock"
    result = d / "result.json"
    ready = d / "ready"
    run = f"b{tag}"
    creds = []
    if auth:
        creds = ["--creds", str(credentials.write(credentials.new_credentials(run, endpoint), d / "run.cred"))]
    tr = Tracked()
    mem = MemSampler()
    cpu = CpuMeter()
    load = os.getloadavg()[0]
    try:
        hub = tr.spawn(
            [
                PY,
                str(BENCH / "bare_hub.py"),
                "--listen",
                endpoint,
                "--run",
                run,
                "--n",
                str(n),
                "--ticks",
                str(ticks),
                "--warmup",
                str(warmup),
                "--result",
                str(result),
                "--join-timeout",
                "90",
                "--linger",
                "2",
                "--ready",
                str(ready),
                *creds,
            ],
            d / "hub.log",
            env,
        )
        handler = ["--handler", env.get("BENCH_CLIENT_HANDLER", "direct")]
        clients = [
            tr.spawn(
                [PY, str(BENCH / "bare_client.py"), str(i), endpoint, run, "--timeout", "240", *creds, *handler],
                d / f"client-{i}.log",
                env,
                own_group=False,
            )
            for i in range(n)
        ]
        cps = [tr.seen[c.pid] for c in clients if c.pid in tr.seen]
        state = {"uss": False}
        hub_p = tr.seen.get(hub.pid)

        def sample():
            mem.sample_rss(cps)
            done = result.exists()
            if ready.exists() and "startup_cpu" not in state:
                state["startup_cpu"] = startup_cpu(cps, {"hub": hub_p})
            if ready.exists() and not state["uss"]:
                cpu.sample({"hub": [hub_p] if hub_p else [], "clients": cps}, every=0.0 if done else 0.25)
            # USS once the hub has written its result and lingers: no ticking is disturbed.
            if not state["uss"] and done:
                state["uss"] = True
                mem.sample_rss(cps, every=0.0)
                mem.sample_uss(cps)

        wait_until(all_exited([hub], sample), 120 + ticks / 20, 0.25)
        wait_until(all_exited(clients), 10, 0.25)
    finally:
        tr.stop()
    if not result.exists():
        return {"n": n, "ok": False, "error": f"hub wrote no result; see {d / 'hub.log'}", "load1": load}
    r = json.loads(result.read_text())
    r.update(load1=load, memory=mem.stats(), cpu=cpu.result(), startup_cpu=state.get("startup_cpu"))
    return r


# -- 2-4. swarm up ---------------------------------------------------------------------------------
FOLLOWER_SPEEDS = [35.0, 50.0, 18.0, 22.0, 30.0, 45.0, 25.0, 40.0]  # m/s, case2's and more like them
LEADERS = [(28.0, 28.0), (40.0, 40.0)]  # (speed m/s, orbit radius m): omega = v / R = 1 rad/s


RING_M = 30.0  # the generated scenario's agents start on a ring of this radius


_RANGES: dict[tuple[int, int, int], float | None] = {}


def sensing_range(n: int, neighbours: int | None, ticks: int = 1500) -> float | None:
    """A sensing range under which each agent of the n-agent ring senses about `neighbours`
    others, on average over the first `ticks` ticks of the run (the swarm spreads out from
    the ring: early frames carry more, later ones fewer); None (unlimited) when that is
    everyone anyway. Found with the batch engine (the same trajectories as `swarm up`):
    scaled by sqrt(wanted / sensed) (sensed grows with the area in range) until within 10%."""
    if neighbours is None or neighbours >= n - 1:
        return None
    if (n, neighbours, ticks) in _RANGES:
        return _RANGES[(n, neighbours, ticks)]

    r = 2 * RING_M * math.sin(math.pi * ((neighbours + 1) // 2 + 0.5) / n)  # that many at the start
    for _ in range(8):
        s = parse_scenario(tomllib.loads(scenario_toml(n, sense_range=r)))
        a = run_batch([s], ticks * DT)[0].recorder.arrays()
        sensed = mean_sensed(a["x"], a["y"], a["alive"], r)
        if abs(sensed - neighbours) <= 0.1 * neighbours:
            break
        r *= math.sqrt(neighbours / max(sensed, 0.1))
    _RANGES[(n, neighbours, ticks)] = r
    return r


def scenario_toml(
    n: int,
    neighbours: int | None = None,
    leaders: int | None = None,
    selection: str = "nearest",
    dt: float = DT,
    duration: float = 60.0,
    sense_range: float | None = None,
    ticks: int = 1500,
) -> str:
    """n agents on a 30 m ring around the target: 1-2 leaders (or `leaders`, evenly
    spaced), the rest followers with `selection`; with `neighbours`, a sensing range under
    which each senses about that many others over the first `ticks` ticks (or `sense_range`)."""
    rng = random.Random(n)
    sr = sense_range if sense_range is not None else sensing_range(n, neighbours, ticks)
    n_leaders = leaders or (1 if n < 4 else 2)
    leader_slots = {round(k * n / n_leaders): k % 2 for k in range(n_leaders)}
    lines = (
        [
            f'name = "bench-{n}"',
            f'description = "benchmarks/bench_runtime.py: {n} agents on a ring, {n_leaders} leader(s)"',
            "",
            "[run]",
            f"dt = {dt}",
            f"duration = {duration}",
            'clock = "lockstep"',
            "seed = 1",
            "",
            "[target]",
            "x = 0.0",
            "y = 0.0",
            "",
            "[gains]",
            "c1 = 1.0",
            "c2 = 0.5",
            "",
            "[sensing]",
            f'selection = "{selection}"',
        ]
        + ([f"range = {sr:.4f}"] if sr else [])
        + [""]
    )
    f = 0
    for k in range(n):
        ang = 2 * math.pi * k / n
        x, y = RING_M * math.cos(ang), RING_M * math.sin(ang)
        heading = math.atan2(
            math.sin(ang + math.pi / 2 + rng.uniform(-0.5, 0.5)), math.cos(ang + math.pi / 2 + rng.uniform(-0.5, 0.5))
        )
        lines += ["[[agents]]", f"id = {k + 1}"]
        if k in leader_slots:
            v, r = LEADERS[leader_slots[k]]
            lines += [
                'role = "leader"',
                f"x = {x:.4f}",
                f"y = {y:.4f}",
                f"heading = {heading:.4f}",
                f"speed = {v}",
                f"orbit_radius = {r}",
                'direction = "ccw"',
                "",
            ]
        else:
            v = FOLLOWER_SPEEDS[f % len(FOLLOWER_SPEEDS)]
            f += 1
            lines += [
                'role = "follower"',
                f"x = {x:.4f}",
                f"y = {y:.4f}",
                f"heading = {heading:.4f}",
                f"speed = {v}",
                "",
            ]
    return "\n".join(lines)


def world_started(out: Path) -> bool:
    try:
        return "start agent None" in (out / "logs" / "world.log").read_text(errors="replace")
    except OSError:
        return False


def mean_contacts(out: Path, sr: float | None) -> float:
    """Mean number of others each live agent sensed per tick over the run (trajectory.npz),
    with sensing range `sr` (None: unlimited)."""

    with np.load(out / "trajectory.npz") as z:
        return mean_sensed(z["x"], z["y"], z["alive"], sr)


def mean_sensed(x, y, alive, sr: float | None) -> float:
    """Mean number of others each live agent senses per tick, over about 200 of the rows of
    recorded (ticks, N) arrays, with sensing range `sr` (None: unlimited)."""

    total = count = 0
    for k in range(0, len(x), max(1, len(x) // 200)):
        a = alive[k].astype(bool)
        if a.sum() < 2:
            continue
        px, py = x[k][a], y[k][a]
        d = np.hypot(px[:, None] - px[None, :], py[:, None] - py[None, :])
        sensed = (d <= sr) if sr else np.ones_like(d, dtype=bool)
        total += int(sensed.sum()) - len(px)
        count += len(px)
    return total / count if count else float("nan")


def run_swarm(
    n: int, ticks: int, work: Path, env: dict, tag: str, profile: float = 0.0, neighbours: int | None = None
) -> dict:
    """One `swarm up`; profile > 0: attach py-spy for that many seconds once ticking."""
    d = work / f"up-{tag}"
    d.mkdir()
    toml = d / f"bench{n}.toml"
    toml.write_text(scenario_toml(n, neighbours, ticks=ticks))
    out = d / "out"
    tr = Tracked()
    mem, wmem = MemSampler(), MemSampler()
    cpu = CpuMeter()
    load = os.getloadavg()[0]
    spies: list[tuple[str, int, subprocess.Popen, Path]] = []
    state: dict = {"started": None, "uss": False, "agents": [], "world": None, "last_discover": 0.0}
    try:
        t_popen = time.time()
        up = tr.spawn(
            [PY, "-m", "swarm", "up", str(toml), "--out", str(out), "--duration", f"{ticks * DT:.6f}", "--no-plots"],
            d / "up.log",
            env,
        )

        def discover():
            kids = tr.discover(up)
            state["agents"] = [k for k in kids if is_agent(k)]
            ws = [k for k in kids if is_world(k)]
            state["world"] = ws[0] if ws else None

        def sample():
            now = time.monotonic()
            if state["started"] is None:
                if now - state["last_discover"] > 1.0:
                    state["last_discover"] = now
                    discover()
                if world_started(out):
                    state["started"] = now
                    discover()  # every agent has joined: all are there now
                    state["startup_cpu"] = startup_cpu(
                        state["agents"], {"world": state["world"], "launcher": tr.seen.get(up.pid)}
                    )
                return
            mem.sample_rss(state["agents"])
            world = [state["world"]] if state["world"] is not None else []
            wmem.sample_rss(world)
            if not spies:  # py-spy itself costs CPU: no accounting once it runs
                cpu.sample({"world": world, "agents": state["agents"], "launcher": [tr.seen[up.pid]]})
            if not state["uss"] and now - state["started"] > 1.0:
                state["uss"] = True
                mem.sample_uss(state["agents"])
                wmem.sample_uss(world)
                if profile > 0:
                    state["targets"] = profile_targets()
                    state["threads0"] = {name: thread_cpu(pr) for name, pr in state["targets"]}
                    state["t_threads0"] = now
            if profile > 0 and "targets" in state and not spies and now - state["t_threads0"] >= 2.0:
                dt = now - state["t_threads0"]
                state["thread_cores"] = {
                    name: thread_cores(state["threads0"][name], thread_cpu(pr), dt) for name, pr in state["targets"]
                }
                start_spies()

        def profile_targets() -> list[tuple[str, psutil.Process]]:
            by_id = {}
            for a in state["agents"]:
                try:
                    by_id[agent_id_of(a.cmdline())] = a
                except psutil.NoSuchProcess:
                    pass
            leader_ids = {1, n // 2 + 1}
            followers = sorted(i for i in by_id if i not in leader_ids)
            t = [
                ("world", state["world"]),
                ("launcher", tr.seen.get(up.pid)),
                ("follower agent", by_id.get(followers[len(followers) // 2]) if followers else None),
                ("leader agent", by_id.get(1)),
            ]
            return [(name, pr) for name, pr in t if pr is not None]

        def start_spies():
            pyspy = shutil.which("py-spy", path=str(Path(PY).parent)) or shutil.which("py-spy")
            if pyspy is None:
                log("py-spy not found: pip install py-spy into the venv for --profile")
                spies.append(("none", 0, None, None))
                return
            for name, pr in state["targets"]:
                raw = d / f"pyspy-{name.replace(' ', '-')}.txt"
                # --idle: every sample of every Python thread; which ones wait is decided from the
                # innermost Python frame (see summarize_pyspy), since py-spy's own idle detection
                # counts threads parked in SimpleQueue.get or zenoh's channels as busy.
                p = tr.spawn(
                    [
                        pyspy,
                        "record",
                        "-p",
                        str(pr.pid),
                        "-d",
                        f"{profile:g}",
                        "-r",
                        "100",
                        "-f",
                        "raw",
                        "--nolineno",
                        "--threads",
                        "--idle",
                        "-o",
                        str(raw),
                    ],
                    d / f"pyspy-{name.replace(' ', '-')}.log",
                    env,
                )
                spies.append((name, pr.pid, p, raw))

        finished = wait_until(all_exited([up], sample), 120 + ticks / 20, 0.25)
        if not finished:
            log(f"swarm up ({n} agents) passed its deadline; stopping it")
        wait_until(all_exited([s[2] for s in spies if s[2] is not None]), profile + 15, 0.25)
    finally:
        tr.stop()
    res: dict = {
        "n": n,
        "ticks_requested": ticks,
        "load1": load,
        "ok": False,
        "memory_agents": mem.stats(),
        "memory_world": wmem.stats(),
        "cpu": cpu.result(drop_last=True),
    }  # the last sample may hold the world's final writing
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError) as e:
        res["error"] = f"no summary.json ({e}); see {d}"
        return res
    start = next((e for e in summary.get("events", []) if e.get("kind") == EventKind.START), None)
    agents = summary.get("agents", {})
    tick_ms = summary.get("tick_ms") or {}  # the world's own per-tick wall time (None: an older world)
    res.update(
        ok=bool(summary.get("completed")) and summary.get("ticks_per_second") is not None,
        completed=summary.get("completed"),
        ticks=summary.get("ticks"),
        ticks_per_second=summary.get("ticks_per_second"),
        tick_ms_p50=tick_ms.get("p50"),
        tick_ms_p99=tick_ms.get("p99"),
        tick_ms_max=tick_ms.get("max"),
        wall_time=summary.get("wall_time"),
        startup_s=start.get("startup_s") if start else None,
        first_tick_s=(start["wall_time"] - t_popen) if start else None,
        missed_ticks=sum(int(a.get("missed_ticks", 0)) for a in agents.values()),
        drops=sum(int(a.get("drops", 0)) for a in agents.values()),
        agent_pids=sorted(int(a["pid"]) for a in agents.values() if a.get("pid")),
        startup_cpu=state.get("startup_cpu"),
    )
    try:
        res["contacts"] = mean_contacts(out, sensing_range(n, neighbours, ticks))
    except (OSError, KeyError, ValueError) as e:
        res["contacts_error"] = str(e)
    if spies:
        res["profile"] = {name: summarize_pyspy(raw, profile) for name, _pid, p, raw in spies if p is not None}
        res["thread_cores"] = state.get("thread_cores")
    return res


# -- profiling -----------------------------------------------------------------------------------
def thread_cpu(pr: psutil.Process) -> dict[int, tuple[str, float]]:
    """tid -> (thread name from /proc, CPU s). Python threads are all called "python"; zenoh's
    Rust threads have their own names (rx-*, tx-*, acc-*, net-*, app-*)."""
    out = {}
    try:
        for t in pr.threads():
            try:
                name = Path(f"/proc/{pr.pid}/task/{t.id}/comm").read_text().strip()
            except OSError:
                name = "?"
            out[t.id] = ("python main" if t.id == pr.pid else name, t.user_time + t.system_time)
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        pass
    return out


def thread_cores(a: dict, b: dict, dt: float) -> dict[str, float]:
    """Cores used per thread kind between two thread_cpu snapshots (main thread = "python main")."""
    kinds: dict[str, float] = defaultdict(float)
    for tid, (name, t1) in b.items():
        if tid in a:
            kind = name if name.startswith("python") else (name.rstrip("0123456789").rstrip("-") or name)
            kinds[kind] += (t1 - a[tid][1]) / dt
    return dict(sorted(kinds.items(), key=lambda kv: -kv[1]))


# Innermost Python frames that mean "waiting": SimpleQueue.get in the main loops, time.sleep in
# the launcher, and a zenoh callback thread parked in its channel (Thread.run calls into Rust).
WAITING = {"World.drain", "AgentNode.loop", "Thread.run", "Launcher.run", "wait_until", "Launcher.connect"}


def summarize_pyspy(raw: Path, seconds: float, rate: int = 100, top: int = 10) -> dict:
    """Per Python thread: share of samples not waiting, hottest functions among those samples."""
    try:
        text = raw.read_text()
    except OSError:
        return {"error": f"no py-spy output {raw}"}
    threads: dict[str, dict] = defaultdict(lambda: {"samples": 0, "busy": 0, "self": Counter(), "incl": Counter()})
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
        if frames[-1].split(" (")[0] in WAITING:
            continue
        t["busy"] += c
        t["self"][frames[-1]] += c
        for f in set(frames):
            t["incl"][f] += c
    out = {}
    for th, t in sorted(threads.items(), key=lambda kv: -kv[1]["busy"]):
        n, b = t["samples"], t["busy"]
        if b == 0:
            continue
        out[th] = {
            "busy_share": b / n,
            "samples": n,
            "busy_samples": b,
            "self": [(f, c / b) for f, c in t["self"].most_common(top)],
            # frames on (nearly) every busy stack are the entry points: leave them out
            "inclusive": [(f, c / b) for f, c in t["incl"].most_common() if c < 0.98 * b][:top],
        }
    return out


# -- report -----------------------------------------------------------------------------------------
def best(runs: list[dict], key: str = "ticks_per_second") -> dict | None:
    ok = [r for r in runs if r.get("ok") and r.get(key)]
    return max(ok, key=lambda r: r[key]) if ok else None


def fmt(v, spec=".0f", none="-"):
    return none if v is None else format(v, spec)


def by_size(results: dict):
    """(N, its results, best baseline run, best swarm run) for each size, in order."""
    for n in results["sizes"]:
        r = results["by_n"][str(n)]
        yield n, r, best(r["baseline"]), best(r["swarm"])


def head(lines: list[str], columns: str, width: int) -> None:
    """A table's column line and the rule under it."""
    lines += [columns, "-" * width]


def report(results: dict) -> str:
    lines = []
    lines.append(
        f"machine: {results['env']['cpus']} CPUs, python {results['env']['python']}, "
        f"zenoh {results['env']['zenoh']}; mode {'quick' if results['quick'] else 'full'}, "
        f"repeat {results['repeat']} (best run shown)"
    )
    lines.append("")
    nb = results.get("neighbours")
    lines.append(
        "sensing: "
        + (
            f"a range under which each agent senses about {nb} others at the start"
            if nb
            else "unlimited (every agent senses every other)"
        )
        + "; 'sensed' = others each agent sensed per tick, mean over the run"
    )
    head(
        lines,
        f"{'N':>3} | {'sensed':>6} | {'baseline ticks/s':>16} | {'swarm ticks/s':>13} | {'ratio':>5} | "
        f"target (>= {TARGET_RATIO}x) met? | all runs: baseline / swarm (ticks/s@cores busy elsewhere)",
        118,
    )
    for n, r, b, s in by_size(results):
        ratio = (s["ticks_per_second"] / b["ticks_per_second"]) if (b and s) else None
        r["ratio"] = ratio
        met = None if ratio is None else ratio >= TARGET_RATIO

        def one(x):
            return f"{fmt(x.get('ticks_per_second'))}@{fmt((x.get('cpu') or {}).get('others_cores'), '.1f')}"

        runs = ", ".join(map(one, r["baseline"])) + " / " + ", ".join(map(one, r["swarm"]))
        lines.append(
            f"{n:>3} | {fmt(s and s.get('contacts'), '.1f'):>6} | "
            f"{fmt(b and b['ticks_per_second']):>16} | {fmt(s and s['ticks_per_second']):>13} | "
            f"{fmt(ratio, '.2f'):>5} | {('yes' if met else 'NO') if met is not None else '-':>24} | {runs}"
        )
    lines.append("")
    if any(r.get("swarm_open") for r in results["by_n"].values()):
        lines.append(
            "cost of the hub's checks (authentication, access rules, size filters): lockstep ticks/s "
            "with them / with an open hub, best runs (target: at most 10% slower)"
        )
        for n, r in results["by_n"].items():
            s, o = best(r["swarm"]), best(r.get("swarm_open", []))
            ratio = (s["ticks_per_second"] / o["ticks_per_second"]) if (s and o) else None
            r["access_ratio"] = ratio
            runs = (
                ", ".join(fmt(x.get("ticks_per_second")) for x in r["swarm"])
                + " / "
                + ", ".join(fmt(x.get("ticks_per_second")) for x in r.get("swarm_open", []))
            )
            lines.append(
                f"{n:>5} agents, swarm up: {fmt(s and s['ticks_per_second'])} / "
                f"{fmt(o and o['ticks_per_second'])} ticks/s = {fmt(ratio, '.3f')} (all runs: {runs})"
            )
            b, ba = best(r["baseline"]), best(r.get("baseline_auth", []))
            bratio = (ba["ticks_per_second"] / b["ticks_per_second"]) if (b and ba) else None
            r["access_ratio_bare"] = bratio
            runs = (
                ", ".join(fmt(x.get("ticks_per_second")) for x in r.get("baseline_auth", []))
                + " / "
                + ", ".join(fmt(x.get("ticks_per_second")) for x in r["baseline"])
            )
            lines.append(
                f"{n:>5} agents, bare:     {fmt(ba and ba['ticks_per_second'])} / "
                f"{fmt(b and b['ticks_per_second'])} ticks/s = {fmt(bratio, '.3f')} (all runs: {runs})"
            )
        lines.append("")
    big = str(max(results["sizes"]))
    sw = [x for x in results["by_n"][big]["swarm"] if x.get("first_tick_s") is not None]
    if sw:
        ft = min(x["first_tick_s"] for x in sw)
        su = min(x["startup_s"] for x in sw)
        lines.append(
            f"first tick, {big} agents: {ft:.2f} s from Popen of `swarm up` (world startup_s {su:.2f} s; "
            f"runs: {', '.join(format(x['first_tick_s'], '.2f') for x in sw)}) vs target "
            f"{TARGET_FIRST_TICK_S:.0f} s: {'met' if ft <= TARGET_FIRST_TICK_S else 'NOT met'}"
        )
        sc = [x["startup_cpu"] for x in sw if x.get("startup_cpu")]
        bb = [x["startup_cpu"] for x in results["by_n"][big]["baseline"] if x.get("startup_cpu")]
        if sc:
            c = sc[-1]
            lines.append(
                f"  CPU used until the first tick: {fmt(c['agents_mean_s'], '.2f')} s per agent process "
                f"({fmt(c['agents_sum_s'], '.1f')} s for {c['agents_n']}), world {fmt(c.get('world_s'), '.2f')} s, "
                f"launcher {fmt(c.get('launcher_s'), '.2f')} s, on {results['env']['cpus']} cores"
            )
        if bb:
            c, b0 = bb[-1], results["by_n"][big]["baseline"][-1]
            lines.append(
                f"  bare baseline: all {big} clients joined {fmt(b0.get('join_s'), '.2f')} s after the hub "
                f"opened; {fmt(c['agents_mean_s'], '.2f')} s CPU per client process until then"
            )
    else:
        lines.append(f"first tick, {big} agents: no successful run")
    lines.append("")
    lines.append(
        f"memory per agent process (target {TARGET_AGENT_MB:.0f} MB); RSS = peak of ~1 s samples while "
        "ticking, USS = one sample while ticking"
    )
    head(
        lines,
        f"{'N':>3} | {'agents':>6} | {'RSS mean':>8} | {'RSS max':>7} | {'USS mean':>8} | {'USS max':>7} | "
        f"{'met (RSS max / USS max)':>24} | bare client RSS mean / USS mean | world RSS / USS",
        130,
    )
    for n, r, _, _ in by_size(results):
        s = next((x for x in r["swarm"] if (x.get("memory_agents") or {}).get("rss")), None)
        b = next((x for x in r["baseline"] if (x.get("memory") or {}).get("rss")), None)
        if s is None:
            lines.append(f"{n:>3} | no samples")
            continue
        ma, mw = s["memory_agents"], s["memory_world"]
        rss, uss = ma["rss"], ma["uss"] or {}
        met = (
            f"{'yes' if rss['max_mb'] <= TARGET_AGENT_MB else 'NO'} / "
            f"{('yes' if uss['max_mb'] <= TARGET_AGENT_MB else 'NO') if uss else '-'}"
        )
        bare = (
            f"{b['memory']['rss']['mean_mb']:.1f} / {fmt((b['memory']['uss'] or {}).get('mean_mb'), '.1f')}"
            if b
            else "-"
        )
        world = f"{fmt((mw['rss'] or {}).get('max_mb'), '.1f')} / {fmt((mw['uss'] or {}).get('max_mb'), '.1f')}"
        lines.append(
            f"{n:>3} | {rss['n']:>6} | {rss['mean_mb']:8.1f} | {rss['max_mb']:7.1f} | "
            f"{fmt(uss.get('mean_mb'), '8.1f'):>8} | {fmt(uss.get('max_mb'), '7.1f'):>7} | {met:>24} | "
            f"{bare:>31} | {world}"
        )
    lines.append("")
    lines.append(
        "CPU while ticking (psutil cpu_times of each process; ms of CPU per tick = cores used / ticks per s; "
        "machine = all cores busy, others = processes not started here)"
    )
    head(
        lines,
        f"{'N':>3} | {'bare: hub':>9} {'clients':>8} {'machine':>8} {'others':>7} | "
        f"{'swarm: world':>12} {'agents':>7} {'launcher':>8} {'machine':>8} {'others':>7}",
        100,
    )
    for n, _r, b, s in by_size(results):

        def per_tick(run, group):
            c = run and run.get("cpu")
            if not c or not run.get("ticks_per_second") or group not in c["cpu_s"]:
                return None
            return 1e3 * c["cpu_s"][group] / c["window_s"] / run["ticks_per_second"]

        def cores(run, key):
            c = run and run.get("cpu")
            return c[key] if c else None

        lines.append(
            f"{n:>3} | {fmt(per_tick(b, 'hub'), '.3f'):>9} {fmt(per_tick(b, 'clients'), '.3f'):>8} "
            f"{fmt(cores(b, 'machine_busy_cores'), '.2f'):>8} {fmt(cores(b, 'others_cores'), '.2f'):>7} | "
            f"{fmt(per_tick(s, 'world'), '.3f'):>12} {fmt(per_tick(s, 'agents'), '.3f'):>7} "
            f"{fmt(per_tick(s, 'launcher'), '.3f'):>8} {fmt(cores(s, 'machine_busy_cores'), '.2f'):>8} "
            f"{fmt(cores(s, 'others_cores'), '.2f'):>7}"
        )
    lines.append(
        "    (ms of CPU per tick; machine/others in cores out of "
        f"{results['env']['cpus']}; bare windows are approximate to ~0.25 s)"
    )
    prof = results.get("profile")
    if prof:
        lines.append("")
        lines.append(
            f"where time goes, {prof['n']} agents (separate run at {fmt(prof.get('ticks_per_second'))} ticks/s "
            "with py-spy attached)"
        )
        lines.append(
            '  CPU by thread over 2 s of ticking (cores; "python main" = the main thread, "python" = '
            "zenoh callback threads, the rest are zenoh's Rust threads):"
        )
        for proc, kinds in (prof.get("thread_cores") or {}).items():
            lines.append(f"    {proc:<15} " + ", ".join(f"{k} {v:.3f}" for k, v in kinds.items() if v >= 0.0005))
        lines.append(
            f"  py-spy, {prof['seconds']:g} s at 100 Hz: busy = share of a thread's samples not waiting; "
            "functions as shares of the busy samples"
        )
        for proc, threads in (prof.get("profile") or {}).items():
            if "error" in threads:
                lines.append(f"    {proc}: {threads['error']}")
                continue
            for th, t in list(threads.items())[:2]:
                lines.append(f"    {proc} [{th}] busy {100 * t['busy_share']:.0f}% of {t['samples']} samples")
                lines.append("      self:      " + "; ".join(f"{f} {100 * c:.0f}%" for f, c in t["self"][:7]))
                lines.append("      inclusive: " + "; ".join(f"{f} {100 * c:.0f}%" for f, c in t["inclusive"][:7]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="swarm up vs bare zenoh: lockstep ticks/s, first tick, memory")
    ap.add_argument("--quick", action="store_true", help="fewer ticks (about a quarter)")
    ap.add_argument("--sizes", default="6,20,50", help="agent counts, comma-separated (default 6,20,50)")
    ap.add_argument("--repeat", type=int, default=None, help="runs of each pair (default 2, quick 1)")
    ap.add_argument(
        "--swarm-seconds",
        type=float,
        default=None,
        help="aim for this many s of ticking per swarm run (default 4, quick 1.5)",
    )
    ap.add_argument(
        "--quiet-wait",
        type=float,
        default=None,
        help="before each run wait up to this many s for the machine to be quiet "
        "(< 0.5 busy cores; default 20, quick 3)",
    )
    ap.add_argument("--profile", action="store_true", help="also profile a 20-agent run with py-spy")
    ap.add_argument("--profile-n", type=int, default=20, help="agents in the --profile run (default 20)")
    ap.add_argument(
        "--neighbours",
        type=int,
        default=None,
        help="give the scenario a sensing range under which each agent senses about this many "
        "others at the start (default: unlimited sensing); the table shows how many it sensed",
    )
    ap.add_argument(
        "--floor-handler",
        choices=("direct", "callback"),
        default="direct",
        help="how the bare clients answer: in their zenoh callback (direct, the default: what "
        "agents do) or from the main thread after a queue (callback: what agents did before)",
    )
    ap.add_argument("--json", type=Path, help="write all results to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the work directory (logs, runs)")
    ap.add_argument(
        "--access-cost",
        action="store_true",
        help="also run swarm up with an open hub (SWARM_OPEN_HUB=1: no authentication, no access "
        "rules, no size filters) after each swarm run, and report the cost of the hub's checks",
    )
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.sizes.split(",") if x.strip()]
    repeat = a.repeat or (1 if a.quick else 2)
    secs = a.swarm_seconds or (1.5 if a.quick else 4.0)
    qwait = a.quiet_wait if a.quiet_wait is not None else (3.0 if a.quick else 20.0)

    def quiet() -> dict:
        return wait_quiet(0.5, qwait) if qwait > 0 else {}

    rt = tempfile.mkdtemp(prefix="sw", dir="/tmp")  # short: Unix socket paths are limited to 108 bytes
    work = Path(tempfile.mkdtemp(prefix="swarm-bench-"))
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt, "PYTHONUNBUFFERED": "1", "BENCH_CLIENT_HANDLER": a.floor_handler}
    results: dict = {
        "quick": a.quick,
        "repeat": repeat,
        "sizes": sizes,
        "swarm_seconds": secs,
        "neighbours": a.neighbours,
        "floor_handler": a.floor_handler,
        "env": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "zenoh": getattr(zenoh, "__version__", None) or _dist_version("eclipse-zenoh"),
            "platform": platform.platform(),
        },
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
                q = quiet()
                b = run_baseline(n, ticks, warmup, work, env, f"{n}-{k}")
                b["quiet"] = q
                r["baseline"].append(b)
                log(
                    f"  -> {fmt(b.get('ticks_per_second'))} ticks/s (others busy before: "
                    f"{fmt(q.get('busy_cores'), '.2f')} cores) {b.get('error', '')}"
                )
                tps = b.get("ticks_per_second") or {6: 3500, 20: 990, 50: 350}.get(n, 20000 / n)
                sticks = int(min(40000, max(300, 0.8 * tps * secs)))
                log(f"[N={n} run {k + 1}/{repeat}] swarm up: {sticks} ticks")
                q = quiet()
                s = run_swarm(n, sticks, work, env, f"{n}-{k}", neighbours=a.neighbours)
                s["quiet"] = q
                r["swarm"].append(s)
                log(
                    f"  -> {fmt(s.get('ticks_per_second'))} ticks/s, first tick {fmt(s.get('first_tick_s'), '.2f')} s"
                    f" (others busy before: {fmt(q.get('busy_cores'), '.2f')} cores) {s.get('error', '')}"
                )
                if a.access_cost:
                    log(f"[N={n} run {k + 1}/{repeat}] bare baseline with the hub's checks")
                    q = quiet()
                    ba = run_baseline(n, ticks, warmup, work, env, f"{n}-{k}-auth", auth=True)
                    ba["quiet"] = q
                    r.setdefault("baseline_auth", []).append(ba)
                    log(f"  -> {fmt(ba.get('ticks_per_second'))} ticks/s {ba.get('error', '')}")
                    log(f"[N={n} run {k + 1}/{repeat}] swarm up, open hub: {sticks} ticks")
                    q = quiet()
                    o = run_swarm(
                        n, sticks, work, {**env, "SWARM_OPEN_HUB": "1"}, f"{n}-{k}-open", neighbours=a.neighbours
                    )
                    o["quiet"] = q
                    r.setdefault("swarm_open", []).append(o)
                    log(f"  -> {fmt(o.get('ticks_per_second'))} ticks/s {o.get('error', '')}")
        if a.profile:
            n = a.profile_n
            b = best(results["by_n"][str(n)]["baseline"]) if str(n) in results["by_n"] else None
            tps = (b or {}).get("ticks_per_second") or {6: 3500, 20: 990, 50: 350}.get(n, 20000 / n)
            seconds = 4.0
            sticks = int(0.8 * tps * (seconds + 4.0))
            log(f"[profile] swarm up, {n} agents, {sticks} ticks, py-spy for {seconds:g} s")
            quiet()
            p = run_swarm(n, sticks, work, env, f"profile-{n}", profile=seconds, neighbours=a.neighbours)
            results["profile"] = {
                "n": n,
                "seconds": seconds,
                "ticks_per_second": p.get("ticks_per_second"),
                "thread_cores": p.get("thread_cores"),
                "profile": p.get("profile"),
                "error": p.get("error"),
            }
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
    return ExitCode.OK


def _dist_version(name: str) -> str | None:

    try:
        return version(name)
    except PackageNotFoundError:
        return None


if __name__ == "__main__":
    sys.exit(main())
