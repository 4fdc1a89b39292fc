"""Each "twin" (a reference implementation and a faster one kept equal to it to the bit)
against its reference, in CPU per tick (a benchmark, not a test).

    python benchmarks/bench_twins.py [--sizes 6,20,100] [--large 200,500] [--reps 5]
                                     [--ticks 200] [--json FILE]

Part 1, in this one process: the Python of a lockstep tick of `swarm up` (the world: frames,
the recording, the commands, the step; every agent: decoding its frame, deciding, encoding
its command), on bench_runtime.py's ring scenario (nearest selection), with unlimited
sensing and with a range under which each agent senses about 8 others, timed in thread CPU
time. The tick runs as shipped and with one twin's fast member swapped for its reference
(the module attribute patched for the run, then put back):

- `C off: encode` / `decode` / `nearest` / `all`: the compiled wire path
  (swarm/contracts/_fastwire.c) against the pure-Python functions `*_py` of wire.py and
  selection.py, the same switch as SWARM_PURE_PYTHON=1 but one function at a time;
- `frames: reference`: every frame built as a `SensorFrame` (sensing.build_frames) and
  encoded one by one (wire.encode_sense), what the world does under faults, instead of
  `wire.encode_sense_rows` (or `encode_sense_pairs` where the grid is used);
- `step: numpy`: kinematics.step on arrays for every swarm, instead of `step_one` agent by
  agent up to STEP_ONE_BY_ONE agents;
- `grid off` (part 1 at --large sizes, with a range only): every pair (`sensing_matrix` and
  `encode_sense_rows`) instead of the grid's sensed pairs (`sensing_pairs` and
  `encode_sense_pairs`) from GRID_MIN_AGENTS agents.

The variants of one size take turns tick by tick in one run (tick k runs variant k mod V:
they give the same bits, so the run stays the shipped run, which is checked), so that each
meets the same load from other processes; a variant's figure is its median tick (a tick
during which the process was preempted costs several times more: noise), and the table the
median over --reps runs. The gain of a twin is (reference - shipped) / reference, in CPU
per tick of the process its code runs in (the world, or one agent; the other column runs
the same code in every variant and is left out: "-") and of the whole swarm (world + N
agents, the saving in that process only). These are the Python parts only (no zenoh; warm
caches unless --cold): a real tick costs more (docs/benchmarks.md#budget), so every share
here is an upper bound of the share in a run.

Part 2: the batch engine (swarm/offline/batch.py) against `swarm sim`'s per-agent engine on
the same ring scenario, one swarm, process CPU per tick, interleaved, best of --reps.

Part 3: agents/cc_plan.py's plan_cc (pure Python, the product) against
tests/support/cc_reference.py (the numpy planner it was ported from, kept by the tests),
per call on leaders' first frames: a leader plans once at its first frame, not per tick.

The machine is shared with other sessions: only ratios measured in the same run count;
the load average is printed before and after. Asserts nothing.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # the repository's swarm, not an installed copy
sys.path.insert(1, str(HERE))
sys.path.insert(2, str(REPO / "tests" / "support"))

import numpy as np  # noqa: E402
from bench_runtime import scenario_toml  # noqa: E402

import swarm.world.core as core_mod  # noqa: E402
from swarm.agents import selection, sticky, sticky_follower  # noqa: E402
from swarm.agents.brain import AgentBrain  # noqa: E402
from swarm.contracts import fastpath, wire  # noqa: E402
from swarm.contracts.brain_config import BrainConf  # noqa: E402
from swarm.contracts.scenario import parse_scenario  # noqa: E402
from swarm.world.engine import Engine  # noqa: E402

clock = time.thread_time_ns
JUNK = np.zeros(8 << 20, np.uint8)  # --cold: written before each process's part of a tick (bench_cold.py)

# name -> [(module, attribute, value)] patched while the variant runs
PATCHES: dict[str, list[tuple[object, str, object]]] = {
    "shipped": [],
    "C off: encode": [
        (wire, "encode_sense_tuples", wire.encode_sense_tuples_py),
        (wire, "encode_sense_rows", wire.encode_sense_rows_py),
        (wire, "encode_sense_pairs", wire.encode_sense_pairs_py),
    ],
    "C off: decode": [(wire, "decode_sense", wire.decode_sense_py)],
    "C off: nearest": [
        (selection, "nearest", selection.nearest_py),
        (sticky, "nearest", selection.nearest_py),
        (sticky_follower, "nearest", selection.nearest_py),
    ],
    "frames: reference": [],  # the tick below builds SensorFrames and encodes them one by one
    "step: numpy": [(core_mod, "STEP_ONE_BY_ONE", 0)],
    "grid off": [(core_mod, "GRID_MIN_AGENTS", 1 << 62)],
}
PATCHES["C off: all"] = PATCHES["C off: encode"] + PATCHES["C off: decode"] + PATCHES["C off: nearest"]
SMALL_VARIANTS = [
    "shipped",
    "C off: all",
    "C off: encode",
    "C off: decode",
    "C off: nearest",
    "frames: reference",
    "step: numpy",
]
LARGE_VARIANTS = ["shipped", "grid off", "C off: all", "frames: reference", "step: numpy"]


@contextlib.contextmanager
def patched(variant: str) -> Iterator[None]:
    todo = [(m, a, v) for m, a, v in PATCHES[variant] if hasattr(m, a)]  # a name gone from a module: skipped
    saved = [(m, a, getattr(m, a)) for m, a, _ in todo]
    try:
        for m, a, v in todo:
            setattr(m, a, v)
        yield
    finally:
        for m, a, v in reversed(saved):
            setattr(m, a, v)


def encode_frames(eng: Engine, reference: bool) -> tuple[list[int], list[bytes]]:
    """The tick's frames as world/process.py's publish_frames encodes them (no faults), or
    through the reference (SensorFrames, one encode_sense each: its path under faults)."""
    c = eng.core
    active = c.active_ids()
    if reference:
        frames = c.frames(active)
        return active, [wire.encode_sense(frames[a]) for a in active]
    rows = [c.index[a] for a in active]
    tx, ty = c.target
    if c.uses_grid():
        i, j, bearing, rng = c.sensed_pairs()
        out = wire.encode_sense_pairs(
            c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, i, j, bearing, rng, c.hops
        )
    else:
        sensed, bearing, rng = c.sensing()
        out = wire.encode_sense_rows(
            c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, sensed, bearing, rng, c.hops
        )
    return active, out


def run_ticks(n: int, neighbours: int | None, ticks: int, variants: list[str], cold: bool, warmup: int = 20) -> dict:
    """us of thread CPU per tick for each variant: the world's, one agent's (mean), the swarm's
    (world + N agents). One run whose ticks take the variants in turn (tick k: variant k mod V),
    so that every variant meets the same load from other processes; each variant's figure is
    its median tick. The variants give the same bits, so the run is the shipped run: its final
    state and frames are checked against a run of the shipped code alone ("same").
    cold: caches evicted (8 MB written, not timed) before the world's two parts of the tick
    and before each agent's, as when 2N + 1 processes take turns on the cores."""
    evict = JUNK.__iadd__ if cold else (lambda _: None)
    total = warmup + ticks * len(variants)
    s = parse_scenario(tomllib.loads(scenario_toml(n, neighbours, ticks=total)))
    out = {}
    for alone in (False, True):
        order = ["shipped"] if alone else variants
        eng = Engine(s, total + 10)
        brains = {a.id: AgentBrain(BrainConf.from_scenario(s, a.id)) for a in s.agents}
        c = eng.core
        world_ns: dict[str, list[int]] = {v: [] for v in order}  # per tick
        agent_ns: dict[str, list[int]] = {v: [] for v in order}  # per tick, every agent's
        sent = 0
        for k in range(total):
            v = order[k % len(order)]
            with patched(v):
                evict(1)
                t0 = clock()
                eng.mark_frames()
                active, frames = encode_frames(eng, v == "frames: reference")
                t1 = clock()
                cmds = []
                spent = 0
                for aid, buf in zip(active, frames):
                    evict(1)
                    a0 = clock()
                    f = wire.decode_sense(buf)
                    d = brains[aid].decide(f)
                    cmds.append(wire.encode_cmd_fields(aid, f.tick, d.u, d.out, d.phase, d.hops, 0))
                    spent += clock() - a0
                evict(1)
                t2 = clock()
                for buf in cmds:
                    cm = wire.decode_cmd(buf)
                    eng.command(cm.agent, cm.tick, cm.u, cm.out, cm.hops)
                eng.end_tick()
                t3 = clock()
            if k >= warmup:
                world_ns[v].append((t1 - t0) + (t3 - t2))
                agent_ns[v].append(spent)
            sent = hash((sent, *frames))
        eng.close()
        digest = hash((sent, c.x.tobytes(), c.y.tobytes(), c.heading.tobytes()))
        if alone:
            same = digest == out.pop("digest")
            for v in variants:
                out[v]["same"] = same
            break
        for v in variants:
            # the median tick: a tick during which this process was preempted (its caches
            # filled by others) costs several times more: on a loaded machine, noise
            world = statistics.median(world_ns[v]) / 1e3
            agent = statistics.median(agent_ns[v]) / n / 1e3
            out[v] = {"world": world, "agent": agent, "swarm": world + n * agent}
        out["digest"] = digest
    return out


def paired(ref: Callable[[], object], fast: Callable[[], object], reps: int, reset=None) -> tuple[float, float]:
    """us of thread CPU per call of each member: `reps` calls of each, taking turns call by
    call (so that both meet the same load), the median of each; reset() (not timed) before
    every call, where a call changes its inputs."""
    ts: dict[int, list[int]] = {0: [], 1: []}
    for r in range(reps):
        for which in (r % 2, 1 - r % 2):
            if reset is not None:
                reset()
            f = fast if which else ref
            t0 = clock()
            f()
            ts[which].append(clock() - t0)
    return statistics.median(ts[0]) / 1e3, statistics.median(ts[1]) / 1e3


def call_pairs(n: int, neighbours: int | None, reps: int, warm_ticks: int = 40) -> list[dict]:
    """Each twin's two members called on the same inputs: the state of a run of the ring
    scenario after `warm_ticks` ticks. Per call us, the calls a tick makes, and the saving per
    tick in the process concerned ("world", or one "agent")."""
    s = parse_scenario(tomllib.loads(scenario_toml(n, neighbours, ticks=warm_ticks + reps)))
    eng = Engine(s, warm_ticks + 10)
    brains = {a.id: AgentBrain(BrainConf.from_scenario(s, a.id)) for a in s.agents}
    c = eng.core
    for _ in range(warm_ticks):
        eng.mark_frames()
        active, frames = encode_frames(eng, False)
        for aid, buf in zip(active, frames):
            d = brains[aid].decide(wire.decode_sense(buf))
            eng.command(aid, c.tick, d.u, d.out, d.hops)
        eng.end_tick()
    active, frames = encode_frames(eng, False)
    decoded = [wire.decode_sense(b) for b in frames]
    out = []

    def add(pair: str, side: str, calls: float, ref: Callable[[], object], fast: Callable[[], object], reset=None):
        r, f = paired(ref, fast, reps, reset)
        out.append({"n": n, "pair": pair, "side": side, "ref_us": r, "fast_us": f, "calls": calls})

    def fresh_sensing() -> None:
        c._sensing = None  # the tick's sensing computed again by the call, as in a tick

    def frames_with(variant: str) -> Callable[[], object]:
        def go() -> object:
            with patched(variant):
                return encode_frames(eng, variant == "frames: reference")

        return go

    ship, again = frames_with("shipped"), fresh_sensing
    add(
        "frames: fast encoders vs build_frames + encode_sense",
        "world",
        1,
        frames_with("frames: reference"),
        ship,
        again,
    )
    add("frames: C vs pure encoder", "world", 1, frames_with("C off: encode"), ship, again)
    if c.uses_grid():
        add("grid + pairs vs every pair + rows", "world", 1, frames_with("grid off"), ship, fresh_sensing)
    k = len(decoded) // 2
    buf, contacts = frames[k], decoded[k].contacts
    add("decode: C vs pure", "agent", 1, lambda: wire.decode_sense_py(buf), lambda: wire.decode_sense(buf))
    add("nearest: C vs pure", "agent", 1, lambda: selection.nearest_py(contacts), lambda: selection.nearest(contacts))
    x, y, g, tick = c.x, c.y, c.heading, c.tick

    def back() -> None:
        c.x, c.y, c.heading, c.tick = x, y, g, tick
        c._sensing = None

    def step_with(limit: int) -> Callable[[], object]:
        def go() -> None:
            core_mod.STEP_ONE_BY_ONE = limit
            try:
                c.step()
            finally:
                core_mod.STEP_ONE_BY_ONE = shipped_limit

        return go

    shipped_limit = core_mod.STEP_ONE_BY_ONE
    if n <= shipped_limit:
        add("step: step_one vs numpy step", "world", 1, step_with(0), step_with(shipped_limit), back)
    back()
    eng.close()
    return out


def batch_vs_sim(n: int, ticks: int, reps: int) -> dict:
    """Process CPU per tick of `swarm sim`'s engine and of the batch engine on one swarm."""
    from swarm.offline.batch import run_batch
    from swarm.offline.sim import run_sim

    s = parse_scenario(tomllib.loads(scenario_toml(n, None, ticks=ticks)))
    dur = ticks * s.run.dt
    out: dict[str, list[float]] = {"sim": [], "batch": []}  # best of reps, as part 1
    same = True
    for _ in range(reps):
        t0 = time.process_time()
        a = run_sim(s, duration=dur)
        t1 = time.process_time()
        b = run_batch([s], duration=dur)[0]
        t2 = time.process_time()
        out["sim"].append((t1 - t0) / ticks * 1e6)
        out["batch"].append((t2 - t1) / ticks * 1e6)
        xa, xb = a.recorder.arrays(), b.recorder.arrays()
        same = same and all(np.array_equal(xa[k], xb[k], equal_nan=True) for k in ("x", "y", "heading"))
    return {"n": n, "sim_us": min(out["sim"]), "batch_us": min(out["batch"]), "same": same}


def cc_plans(reps: int) -> dict:
    """us per plan_cc call, the product's against the test reference, on 50 leaders' starts."""
    import cc_reference

    from swarm.agents.cc_plan import plan_cc

    rs = np.random.default_rng(3)
    count = 50
    cases = [
        (float(x), float(y), float(g), 1.0, 10.0, float(d), None)
        for x, y, g, d in zip(
            rs.uniform(-40, 40, count),
            rs.uniform(-40, 40, count),
            rs.uniform(-3, 3, count),
            rs.choice([-1.0, 1.0], count),
        )
    ]
    ts: dict[str, list[float]] = {"pure": [], "numpy": []}
    for _ in range(reps):
        for name, f in (("pure", plan_cc), ("numpy", cc_reference.plan_cc)):
            t0 = time.process_time()
            for c in cases:
                f(*c)
            ts[name].append((time.process_time() - t0) / len(cases) * 1e6)
    return {k: min(v) for k, v in ts.items()}


# where each variant's code runs: its saving is read in that process's column only (the other
# column of a tick runs the same code in every variant; its differences are noise, and the
# interference of one process's code with the other's caches, which separate processes do not have)
SIDE = {"C off: encode": "world", "C off: decode": "agent", "C off: nearest": "agent", "C off: all": "both"}


def gains(variant: str, m: dict, base: dict, n: int) -> dict:
    """The fast member's gain over its reference, (reference - shipped) / reference, in CPU per
    tick of the process it runs in and of the whole swarm (world + N agents)."""
    side = SIDE.get(variant, "world")
    saved_world = m["world"] - base["world"] if side in ("world", "both") else 0.0
    saved_agent = m["agent"] - base["agent"] if side in ("agent", "both") else 0.0
    ref_swarm = base["swarm"] + saved_world + n * saved_agent
    return {
        "gain_world": gain(base["world"] + saved_world, base["world"]) if side != "agent" else math.nan,
        "gain_agent": gain(base["agent"] + saved_agent, base["agent"]) if side != "world" else math.nan,
        "gain_swarm": gain(ref_swarm, base["swarm"]),
    }


def gain(ref: float, fast: float) -> float:
    return (ref - fast) / ref if ref > 0 else math.nan


def load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="6,20,100")
    ap.add_argument("--large", default="200,500", help="sizes for the grid (sensing with a range); '' to skip")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--skip", default="", help="parts to skip: calls,ticks,batch,cc")
    ap.add_argument("--calls", type=int, default=400, help="calls of each member per pair (part 0)")
    ap.add_argument("--cold", action="store_true", help="part 1 with caches evicted before each process's part")
    ap.add_argument("--variants", default="", help="part 1: only these variants (comma-separated), and shipped")
    ap.add_argument("--sensing", default="unlimited,8", help="part 1: 'unlimited' and/or neighbours in sight")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--commit", default="", help="the commit to print (a tree exported with git archive has no .git)")
    a = ap.parse_args(argv)
    skip = set(filter(None, a.skip.split(",")))
    commit = (
        a.commit
        or subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
    )
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"# {when}, commit {commit}, {platform.processor() or platform.machine()},")
    print(f"# {os.cpu_count()} cores, Python {platform.python_version()}, wire path: {fastpath.path}; load {load()}")
    results: dict = {"commit": commit, "calls": [], "ticks": [], "batch": [], "cc": None}
    plan = []
    if "ticks" not in skip:
        only = set(filter(None, a.variants.split(",")))
        pick = [v for v in SMALL_VARIANTS if not only or v in only or v == "shipped"]
        sensing = [None if k == "unlimited" else int(k) for k in a.sensing.split(",")]
        plan += [(n, nb, pick) for n in map(int, filter(None, a.sizes.split(","))) for nb in sensing]
        pick = [v for v in LARGE_VARIANTS if not only or v in only or v == "shipped"]
        plan += [(n, 8, pick) for n in map(int, filter(None, a.large.split(",")))]
    for n, nb, variants in plan:
        runs: dict[str, list[dict]] = {v: [] for v in variants}
        for rep in range(a.reps):  # the order turned by one each time
            order = variants[rep % len(variants) :] + variants[: rep % len(variants)]
            got = run_ticks(n, nb, a.ticks, order, a.cold)
            for v in variants:
                runs[v].append(got[v])
        # the median over the reps of each variant's median tick
        med = {
            v: {k: statistics.median(r[k] for r in rs) for k in ("world", "agent", "swarm")} for v, rs in runs.items()
        }
        same = {v: all(r["same"] for r in rs) for v, rs in runs.items()}
        sens = "unlimited" if nb is None else f"~{nb} others"
        base = med["shipped"]
        cold = ", cold caches" if a.cold else ""
        print(
            f"\nN = {n}, sensing {sens}{cold}: us per tick, medians of {a.reps} runs "
            f"(shipped: world {base['world']:.1f}, agent {base['agent']:.2f}, swarm {base['swarm']:.0f}); load {load()}"
        )
        print(
            f"{'variant (reference in place of)':34} {'world':>8} {'agent':>8} {'swarm':>9} "
            f"{'gain world':>11} {'gain agent':>11} {'gain swarm':>11} same"
        )
        for v in variants:
            m = med[v]
            row = {"n": n, "sensing": sens, "cold": a.cold, "variant": v, **m, "same_bits": same[v], "reps": runs[v]}
            if v != "shipped":
                row.update(gains(v, m, base, n))
            results["ticks"].append(row)
            g = (
                ""
                if v == "shipped"
                else "".join(
                    f" {'-':>11}" if math.isnan(row[f"gain_{k}"]) else f" {100 * row[f'gain_{k}']:10.1f}%"
                    for k in ("world", "agent", "swarm")
                )
            )
            print(f"{v:34} {m['world']:8.1f} {m['agent']:8.2f} {m['swarm']:9.0f}{g} {same[v]}")
    if "calls" not in skip:
        print(
            f"\ncalls: each pair's members on the same inputs, taking turns call by call, medians of {a.calls};"
            "\nsaved = (reference - fast) x calls per tick; share = saved / (shipped tick + saved), the tick"
            "\nof the process concerned (its median tick in a shipped run; swarm: world + N agents)"
        )
        print(
            f"{'N':>4} {'sensing':10} {'pair':52} {'ref us':>9} {'fast us':>9} {'saved/tick':>10} "
            f"{'share proc':>10} {'share swarm':>11}"
        )
        for n in map(int, filter(None, (a.sizes + "," + a.large).split(","))):
            for nb in [None, 8] if n in map(int, filter(None, a.sizes.split(","))) else [8]:
                base = run_ticks(n, nb, a.ticks, ["shipped"], False)["shipped"]
                for r in call_pairs(n, nb, a.calls):
                    saved = (r["ref_us"] - r["fast_us"]) * r["calls"]
                    proc = base[r["side"]]
                    swarm_saved = saved * (n if r["side"] == "agent" else 1)
                    r.update(
                        sensing="unlimited" if nb is None else f"~{nb} others",
                        saved_us=saved,
                        tick_us=proc,
                        swarm_us=base["swarm"],
                        share_proc=saved / (proc + saved),
                        share_swarm=swarm_saved / (base["swarm"] + swarm_saved),
                    )
                    results["calls"].append(r)
                    print(
                        f"{n:4} {r['sensing']:10} {r['pair']:52} {r['ref_us']:9.2f} {r['fast_us']:9.2f} "
                        f"{saved:10.2f} {100 * r['share_proc']:9.1f}% {100 * r['share_swarm']:10.1f}%"
                    )
    if "batch" not in skip:
        print(f"\nbatch engine vs swarm sim (one swarm, unlimited sensing, process CPU per tick, best of {a.reps}):")
        print(f"{'N':>4} {'sim us':>9} {'batch us':>9} {'gain':>7} identical")
        for n in map(int, filter(None, a.sizes.split(","))):
            r = batch_vs_sim(n, a.ticks * 2, a.reps)
            r["gain"] = gain(r["sim_us"], r["batch_us"])
            results["batch"].append(r)
            print(f"{n:4} {r['sim_us']:9.0f} {r['batch_us']:9.0f} {100 * r['gain']:6.1f}% {r['same']}")
    if "cc" not in skip:
        r = cc_plans(a.reps)
        results["cc"] = r
        print(
            f"\nplan_cc per call (once per leader per run): pure Python {r['pure']:.0f} us, "
            f"numpy reference {r['numpy']:.0f} us"
        )
    print(f"\n# load at the end {load()}")
    if a.json:
        a.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
