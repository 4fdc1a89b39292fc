"""VMAS against swarm on the same job: agent-steps per second at B parallel environments.

Run from the benchmark's own venv (benchmarks/vmas/README.md: torch, vmas and the project):

    /tmp/vmasvenv/bin/python benchmarks/vmas/bench_vmas.py                 # B = 1, 16, 256, 4096, 3 reps
    /tmp/vmasvenv/bin/python benchmarks/vmas/bench_vmas.py --sizes 1,16 --repeat 2 --json out.json
    /tmp/vmasvenv/bin/python benchmarks/vmas/bench_vmas.py --profile 256   # cProfile the swarm side at B
    /tmp/vmasvenv/bin/python benchmarks/vmas/bench_vmas.py --check   # the VMAS scenario against swarm's maths

The job (circumnav_vmas.py's docstring): 10 unicycles at constant speed steered by turn
rate, 2 leaders and 8 followers, swarm.env's default reward, dt = 0.05 s. Contenders:

- vmas-1t / vmas-2t: `vmas.make_env(Circumnav(), num_envs=B, device="cpu")`, torch on 1 or
  2 threads, every agent's action a constant turn rate of 0.5 rad/s (no reset in the window).
- SwarmEnv: swarm.env's PettingZoo env on `random_swarm(SwarmSetting(n=10), seed)`,
  agents="all" (all 10 take actions, 0.5 rad/s), B copies stepped one after the other in a
  loop (B <= --env-max, the loop's rate does not depend on B).
- VectorSwarmEnv: swarm.env's vectorised env (when the installed swarm has one), B swarms
  as arrays, agents="all", actions (B, 10) of 0.5 rad/s.
- study: `swarm.study.run_swarms(n=10, seeds=B, duration=--study-duration, workers=2)`,
  the batch engine in a process pool running the paper's control law itself (no actions);
  the whole call, pool start and CSV included. Its figure is simulated agent-seconds per
  wall second; agent-steps = agent-seconds / dt. B <= --study-max.

Every env contender is built and reset before the clock starts, warmed by 2 steps, then
stepped until --window seconds have passed (at least 3 steps): agent-steps/s = B x 10 x
steps / wall. Repetitions are interleaved (for each repetition, each B, each contender in
turn: ABAB...), medians reported with the spread; the ratio is the best swarm environment
(SwarmEnv or VectorSwarmEnv: the study runs its own control law, not actions, observations
and rewards) over the best VMAS one at that B, from the same run, of the medians and
repetition by repetition (the contenders of one repetition ran back to back: steadier on a
shared machine). Nothing here asserts.
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import json
import math
import os
import platform
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

AGENTS = 10
LEADERS = 2
DT = 0.05
TURN = 0.5  # rad/s: every agent's constant action
ENV_DURATION = 500.0  # s: episodes of the env contenders (10,000 steps: no reset inside a window)

Step = Callable[[], None]
ENVS = ("SwarmEnv", "VectorSwarmEnv")  # swarm's contenders doing VMAS's job (the study runs its own law)


SELECTION = ["nearest"]  # the swarm side's selection rule (--selection): nearest is what Circumnav does


def setting(duration: float):
    from swarm.study.swarms import SwarmSetting

    return SwarmSetting(n=AGENTS, leaders=LEADERS, selection=SELECTION[0], duration=duration, dt=DT)


# -- contenders: build(B) -> step function (one step of all B environments) ----------------------


def build_vmas(b: int) -> Step:
    import torch
    import vmas
    from circumnav_vmas import Circumnav

    env = vmas.make_env(Circumnav(), num_envs=b, device="cpu", seed=0, dt=DT, n_agents=AGENTS, n_leaders=LEADERS)
    env.reset()
    actions = [torch.full((b, 1), TURN) for _ in range(AGENTS)]

    def step() -> None:
        env.step(actions)

    return step


def build_swarmenv(b: int) -> Step:
    from swarm.env import SwarmEnv
    from swarm.study.swarms import random_swarm

    envs = [SwarmEnv(random_swarm(setting(ENV_DURATION), seed), agents="all") for seed in range(b)]
    for seed, e in enumerate(envs):
        e.reset(seed=seed)
    actions = {n: np.full(1, TURN, dtype=np.float32) for n in envs[0].possible_agents}

    def step() -> None:
        for e in envs:
            e.step(actions)
            if not e.agents:
                e.reset()

    return step


def vector_env_class():
    try:
        from swarm.env.vector import VectorSwarmEnv
    except ImportError:
        return None
    return VectorSwarmEnv


def build_vector(b: int) -> Step:
    from swarm.study.swarms import random_swarm

    cls = vector_env_class()
    assert cls is not None
    env = cls(
        random_swarm(setting(ENV_DURATION), 0),
        num_envs=b,
        seed=0,
        agents="all",
        position_jitter=30.0,
        heading_jitter=math.pi,
    )
    obs, _ = env.reset()
    actions = np.full(obs.shape[:2], TURN)

    def step() -> None:
        env.step(actions)

    return step


def timed_steps(step: Step, b: int, window: float) -> float:
    """agent-steps per second of `step` (B environments of AGENTS agents each)."""
    step()
    step()
    n, t0 = 0, time.perf_counter()
    while True:
        step()
        n += 1
        wall = time.perf_counter() - t0
        if wall >= window and n >= 3:
            return b * AGENTS * n / wall


def study_rate(b: int, duration: float, workers: int) -> float:
    """Simulated agent-seconds per wall second of `run_swarms` on B seeds."""
    import swarm.study as study

    with tempfile.TemporaryDirectory(prefix="vmasbench") as d:
        t0 = time.perf_counter()
        r = study.run_swarms(
            n=AGENTS,
            leaders=LEADERS,
            selection=SELECTION[0],
            seeds=b,
            duration=duration,
            dt=DT,
            workers=workers,
            out=Path(d) / "study",
            plot=False,
            progress=False,
            say=lambda _: None,
        )
        wall = time.perf_counter() - t0
    if len(r.finished) != b:
        raise RuntimeError(f"study: {len(r.finished)} rows for {b} seeds")
    return b * AGENTS * duration / wall


# -- the run -------------------------------------------------------------------------------------


def describe_machine() -> dict:
    import numpy
    import torch
    import vmas

    import swarm

    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "?")
    src = Path(swarm.__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "-C", str(src), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(src), "status", "--porcelain", "--untracked-files=no", "--", "swarm", "agents", "world"],
            capture_output=True,
            text=True,
        ).stdout.strip()
        commit += " (+ uncommitted changes in swarm/agents/world)" if dirty else ""
    except (OSError, subprocess.CalledProcessError):
        commit = "?"
    return {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "swarm_source": str(src),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "vmas": getattr(vmas, "__version__", "?"),
        "numpy": numpy.__version__,
    }


def fmt(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.1f} k" if x >= 1e3 else f"{x:.0f}"


def cell(vals: list[float]) -> str:
    if not vals:
        return "-"
    med = statistics.median(vals)
    return fmt(med) if len(vals) == 1 else f"{fmt(med)} ({fmt(min(vals))}-{fmt(max(vals))})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1,16,256,4096", help="B values, comma-separated")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved repetitions (default 3)")
    ap.add_argument("--window", type=float, default=1.5, help="seconds of stepping per measurement")
    ap.add_argument("--env-max", type=int, default=16, help="largest B for the SwarmEnv loop")
    ap.add_argument("--study-max", type=int, default=256, help="largest B for the study")
    ap.add_argument("--study-duration", type=float, default=20.0, help="simulated s of each study run")
    ap.add_argument("--study-workers", type=int, default=2)
    ap.add_argument(
        "--selection",
        default="nearest",
        choices=["nearest", "sticky", "rooted"],
        help="the swarm side's out-neighbour rule (default nearest: the rule the VMAS scenario implements)",
    )
    ap.add_argument("--skip", default="", help="contenders to leave out, comma-separated")
    ap.add_argument("--json", type=Path, help="write every measurement there")
    ap.add_argument("--check", action="store_true", help="only compare the VMAS scenario with swarm's functions")
    ap.add_argument("--profile", type=int, metavar="B", help="only cProfile the swarm contenders at this B")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    SELECTION[0] = args.selection
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    import torch

    if args.check:
        check()
        return
    if args.profile:
        profile(args.profile, args)
        return

    builders: dict[str, tuple[Callable[[int], Step], int]] = {
        "vmas-1t": (build_vmas, max(sizes)),
        "vmas-2t": (build_vmas, max(sizes)),
        "SwarmEnv": (build_swarmenv, args.env_max),
    }
    threads = {"vmas-1t": 1, "vmas-2t": 2}  # torch's intra-op threads while that contender steps
    if vector_env_class() is not None:
        builders["VectorSwarmEnv"] = (build_vector, max(sizes))
    builders = {k: v for k, v in builders.items() if k not in skip}
    machine = describe_machine()
    print(f"# {machine['date']}, swarm {machine['commit']} ({machine['swarm_source']})", flush=True)
    print(
        f"# {machine['cpu']}, {machine['cores']} cores, Python {machine['python']}, torch {machine['torch']}, "
        f"vmas {machine['vmas']}, numpy {machine['numpy']}",
        flush=True,
    )
    steps: dict[tuple[str, int], Step] = {}
    torch.set_num_threads(1)  # building: two threads crawl on a loaded machine
    for name, (build, most) in builders.items():
        for b in sizes:
            if b <= most:
                t0 = time.perf_counter()
                same = "vmas-1t" if name == "vmas-2t" else None  # one VMAS env for both thread counts
                steps[name, b] = steps[same, b] if (same, b) in steps else build(b)
                print(f"built {name} B={b} in {time.perf_counter() - t0:.1f} s", flush=True)
    rates: dict[tuple[str, int], list[float]] = {k: [] for k in steps}
    study_b = [b for b in sizes if b <= args.study_max] if "study" not in skip else []
    for b in study_b:
        rates["study", b] = []
    loads = [os.getloadavg()[0]]
    for rep in range(args.repeat):
        for b in sizes:
            for name in [*builders, "study"]:
                if (name, b) not in rates:
                    continue
                if name == "study":
                    r = study_rate(b, args.study_duration, args.study_workers) / DT
                else:
                    torch.set_num_threads(threads.get(name, 1))
                    r = timed_steps(steps[name, b], b, args.window)
                rates[name, b].append(r)
                print(f"rep {rep + 1} B={b:<5} {name:<15} {fmt(r):>9} agent-steps/s", flush=True)
        loads.append(os.getloadavg()[0])
    torch.set_num_threads(2)
    names = [*builders, *(["study"] if study_b else [])]
    print()
    print(f"{machine['date']}, swarm commit {machine['commit']}, {machine['cpu']} ({machine['cores']} cores), ")
    print(f"Python {machine['python']}, torch {machine['torch']} (CPU), vmas {machine['vmas']}; ")
    print(
        f"swarm's selection rule: {args.selection}; 1-min load average during the run: "
        f"{min(loads):.1f}-{max(loads):.1f} (uptime)"
    )
    print()
    print("agent-steps per second, median of", args.repeat, "interleaved repetitions (min-max):")
    print()
    print("| B | " + " | ".join(names) + " | best swarm env / best VMAS | the same, per repetition |")
    print("| --- " * (len(names) + 3) + "|")
    summary = []
    for b in sizes:
        med = {n: statistics.median(rates[n, b]) for n in names if rates.get((n, b))}
        best_v = max((med[n] for n in med if n.startswith("vmas")), default=None)
        best_s = max((med[n] for n in med if n in ENVS), default=None)
        ratio = f"{best_s / best_v:.2f}x" if best_v and best_s else "-"
        # the ratio within each repetition (its contenders ran back to back): steadier under load
        per = [
            max(rates[n, b][k] for n in med if n in ENVS) / max(rates[n, b][k] for n in med if n.startswith("vmas"))
            for k in range(args.repeat)
            if best_v and best_s
        ]
        per_cell = f"{statistics.median(per):.2f}x ({min(per):.2f}-{max(per):.2f})" if per else "-"
        print(f"| {b} | " + " | ".join(cell(rates.get((n, b), [])) for n in names) + f" | {ratio} | {per_cell} |")
        summary.append({"B": b, "median": med, "ratio": ratio, "ratio_per_rep": per})
    if study_b:
        print()
        print(
            f"study: run_swarms(n={AGENTS}, seeds=B, duration={args.study_duration:g} s, workers="
            f"{args.study_workers}); in simulated agent-seconds per wall second: "
            + ", ".join(f"B={b}: {fmt(statistics.median(rates['study', b]) * DT)}" for b in study_b)
        )
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "machine": machine,
                    "loads": loads,
                    "args": {k: str(v) for k, v in vars(args).items()},
                    "rates": {f"{n}@{b}": v for (n, b), v in rates.items()},
                    "summary": summary,
                },
                indent=1,
            )
        )


def check() -> None:
    """The VMAS scenario against swarm's own functions on one swarm: 20 steps of its unicycles
    against swarm.world.kinematics.step, then its rewards against swarm.env's
    radial_rate_reward on the same state (out-neighbours: nearest, as Circumnav chooses)."""
    import torch
    import vmas
    from circumnav_vmas import Circumnav

    from swarm.contracts.orbits import roots
    from swarm.env.parallel import WorldView, radial_rate_reward
    from swarm.world.kinematics import step as arc_step

    sc = Circumnav()
    env = vmas.make_env(sc, num_envs=1, device="cpu", seed=3)
    env.reset()

    def state() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pos = np.array([a.state.pos[0].tolist() for a in env.world.agents])
        return pos[:, 0], pos[:, 1], np.array([a.state.rot[0, 0].item() for a in env.world.agents])

    x, y, h = state()
    v = sc.speed[0].numpy().astype(float)
    u = np.linspace(-2.0, 2.0, AGENTS)
    for _ in range(20):
        x, y, h = arc_step(x, y, h, v, u, DT)
        env.step([torch.tensor([[float(ui)]]) for ui in u])
    vx, vy, vh = state()
    print(f"20 steps, |VMAS - swarm kinematics|: {max(np.abs(vx - x).max(), np.abs(vy - y).max()):.1e} m, ", end="")
    print(f"{np.abs(np.angle(np.exp(1j * (vh - h)))).max():.1e} rad (float32 against float64)")
    pos = np.stack([vx, vy], axis=1)
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    out = np.array([k if k < LEADERS else int(d[k].argmin()) for k in range(AGENTS)])
    lead = np.arange(AGENTS) < LEADERS
    root = roots({k + 1: None if lead[k] else int(out[k]) + 1 for k in range(AGENTS)}, set(range(1, LEADERS + 1)))
    view = WorldView(
        20, 20 * DT, np.arange(1, AGENTS + 1), {k + 1: k for k in range(AGENTS)}, vx, vy, vh, v, u,
        np.ones(AGENTS, bool), out, lead, np.where(lead, v, np.nan), lead.astype(float), (0.0, 0.0), root,
    )  # fmt: skip
    reward = radial_rate_reward()
    ours = np.array([reward(view, k + 1) for k in range(AGENTS)])
    theirs = sc.rewards[0].numpy().astype(float)
    print(f"rewards, swarm.env: {np.round(ours, 4).tolist()}")
    print(f"rewards, VMAS:      {np.round(theirs, 4).tolist()}; largest difference {np.abs(ours - theirs).max():.1e}")


def profile(b: int, args: argparse.Namespace) -> None:
    """cProfile one window of each swarm contender at B (and one study run), top entries."""
    jobs: list[tuple[str, Callable[[], object]]] = []
    if b <= args.env_max:
        s = build_swarmenv(b)
        jobs.append(("SwarmEnv", lambda: timed_steps(s, b, args.window)))
    if vector_env_class() is not None:
        v = build_vector(b)
        jobs.append(("VectorSwarmEnv", lambda: timed_steps(v, b, args.window)))
    if b <= args.study_max:
        from swarm.study.batch import run_swarm_chunk

        chunk = (setting(args.study_duration), tuple(range(min(b, 64))))
        jobs.append(("study chunk (one worker's batch)", lambda: run_swarm_chunk(chunk)))
    for name, job in jobs:
        prof = cProfile.Profile()
        prof.enable()
        job()
        prof.disable()
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(14)
        print(f"## {name}, B = {b}\n" + out.getvalue())


if __name__ == "__main__":
    main()
