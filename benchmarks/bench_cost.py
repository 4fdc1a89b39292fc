"""CPU per lockstep tick, part by part, of the world and of one agent (a benchmark, not a test).

    python benchmarks/bench_cost.py [--sizes 6,100] [--ticks 400] [--neighbours 8]
                                    [--selection nearest] [--tree DIR] [--json FILE]
    python benchmarks/bench_cost.py --compare OLD_TREE [--reps 3] [...]

In this one process, on bench_runtime.py's ring scenario with N agents (unlimited sensing, and
a range under which each agent senses about --neighbours others), the code that runs each
tick of `swarm up`, with the world process's choices (the matrices and
`wire.encode_sense_rows` at every N, or with --pairs the sensed pairs where the grid is
used, as the world does; an older --tree whose world built up to 8 agents' frames pair by
pair is measured through the matrices too; the recording
deferred and streamed to an MCAP file), timed part by part in thread CPU time (what other
processes on the machine do is not counted; the cost of reading the clock is taken off):

- world: `sensing` (WorldCore.sensing: who senses whom, bearings, ranges), `encode` (every
  active agent's frame), `record` (the recording's per-tick work: the deferred copy and the
  MCAP write), `commands` (every command decoded and latched), `step` (integration);
- one agent (the mean over the agents): `decode` (wire.decode_sense), `select` (decide minus
  the law: selection and the brain's bookkeeping), `law`, `encode` (its command).

The messaging is not here (bench_runtime.py). Warm caches, one core: in a real run 2N + 1
processes share the cores and every figure is larger; read the parts and their growth.

`--tree DIR` imports `swarm` from another checkout (e.g. a clone at an older commit);
`--compare OLD_TREE` runs this script on OLD_TREE and on this checkout in turn, `--reps`
times, interleaved, and prints both (before = OLD_TREE). `--pairs`: where the world senses
through the grid it encodes its frames from `WorldCore.sensed_pairs` with
`wire.encode_sense_pairs` (no (N, N) matrices), as world/process.py does since it took that
path; without it, from the matrices, as before (with --compare: OLD_TREE without, this
checkout with).
`--scaling`: the cost model's constants against N and K (warm, best of many calls)
instead. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import timeit
import tomllib
from functools import partial
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def _tree_from_argv() -> Path:
    for k, arg in enumerate(sys.argv):
        if arg == "--tree" and k + 1 < len(sys.argv):
            return Path(sys.argv[k + 1]).resolve()
        if arg.startswith("--tree="):
            return Path(arg.split("=", 1)[1]).resolve()
    return REPO


TREE = _tree_from_argv()
sys.path.insert(0, str(TREE))  # the swarm package measured: this checkout's, or --tree's ...
import swarm  # noqa: E402  (... imported before bench_runtime puts this checkout first on sys.path)

sys.path.insert(1, str(HERE))
import numpy as np  # noqa: E402
from bench_runtime import scenario_toml  # noqa: E402

from swarm.agents.brain import AgentBrain  # noqa: E402
from swarm.agents.selection import nearest  # noqa: E402
from swarm.contracts import wire  # noqa: E402
from swarm.contracts.brain_config import BrainConf  # noqa: E402
from swarm.contracts.frames import Contact, SensorFrame  # noqa: E402
from swarm.contracts.scenario import parse_scenario  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.world.engine import Engine  # noqa: E402
from swarm.world.recording import DeferredRecorder  # noqa: E402
from swarm.world.sensing import sensing_matrix  # noqa: E402

WORLD_PARTS = ("sensing", "encode", "record", "commands", "step")
AGENT_PARTS = ("decode", "select", "law", "encode")
clock = time.thread_time_ns


def clock_cost(samples: int = 20000) -> float:
    """ns that one interval measured with `clock` adds by itself (the clock's own cost)."""
    best = float("inf")
    for _ in range(5):
        t0 = clock()
        for _ in range(samples):
            clock()
        best = min(best, (clock() - t0) / samples)
    return best


class TimedLaw:
    """An agent's law, with the (thread CPU) time spent in it summed."""

    def __init__(self, law, overhead: float):
        self.law = law
        self.overhead = overhead
        self.ns = 0.0

    def __call__(self, obs):
        t0 = clock()
        u = self.law(obs)
        self.ns += clock() - t0 - self.overhead
        return u


def measure(n: int, neighbours: int | None, ticks: int, selection: str, warmup: int = 50, pairs: bool = False) -> dict:
    s = parse_scenario(tomllib.loads(scenario_toml(n, neighbours, selection=selection, ticks=ticks + warmup)))
    tmp = Path(tempfile.mkdtemp(prefix="bench_cost"))
    eng = Engine(s, ticks + warmup + 10, recording=tmp / "recording.mcap")
    rec = DeferredRecorder(eng.rec)
    eng.rec = rec
    brains = {a.id: AgentBrain(BrainConf.from_scenario(s, a.id)) for a in s.agents}
    overhead = clock_cost()
    laws = {}
    for aid, b in brains.items():
        laws[aid] = b.law = TimedLaw(b.law, overhead)
    c = eng.core
    sens = s.sensing
    world = dict.fromkeys(WORLD_PARTS, 0)
    agent = dict.fromkeys(AGENT_PARTS, 0)
    contacts = 0
    for k in range(ticks + warmup):
        on = k >= warmup
        law_before = sum(t.ns for t in laws.values())
        t0 = clock()
        eng.mark_frames()
        active = c.active_ids()
        rows = [c.index[a] for a in active]
        if pairs and c.uses_grid():  # what world/process.py does where the grid is used
            found = c.sensed_pairs()
            t1 = clock()
            tx, ty = c.target
            frames = wire.encode_sense_pairs(
                c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, *found, c.hops
            )
        else:
            sensed, bearing, rng = c.sensing()
            t1 = clock()
            tx, ty = c.target
            frames = wire.encode_sense_rows(
                c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, sensed, bearing, rng, c.hops
            )
        t2 = clock()
        rec.flush()  # the last tick's recording, while the agents answer (world/process.py)
        t3 = clock()
        decoded = [wire.decode_sense(buf) for buf in frames]
        t4 = clock()
        decisions = [brains[aid].decide(f) for aid, f in zip(active, decoded)]
        t5 = clock()
        cmds = [
            wire.encode_cmd_fields(aid, f.tick, d.u, d.out, d.phase, d.hops, 0)
            for aid, f, d in zip(active, decoded, decisions)
        ]
        t6 = clock()
        for buf in cmds:
            cm = wire.decode_cmd(buf)
            eng.command(cm.agent, cm.tick, cm.u, cm.out, cm.hops)
        t7 = clock()
        u = c.applied()  # Engine.end_tick, its parts timed apart
        rec.record(c.tick, c.time, c.x, c.y, c.heading, u, eng.out, c.alive_mask(), eng.missed_now)
        eng.missed_now = 0
        t8 = clock()
        c.step()
        t9 = clock()
        if not on:
            continue
        law_ns = sum(t.ns for t in laws.values()) - law_before  # within decide: taken off select
        contacts += sum(len(f.contacts) for f in decoded)
        world["sensing"] += t1 - t0 - overhead
        world["encode"] += t2 - t1 - overhead
        world["record"] += (t3 - t2) + (t8 - t7) - 2 * overhead
        world["commands"] += t7 - t6 - overhead
        world["step"] += t9 - t8 - overhead
        agent["decode"] += t4 - t3 - overhead
        agent["select"] += t5 - t4 - overhead - law_ns - 2 * overhead * len(active)  # and TimedLaw's clocks
        agent["law"] += law_ns
        agent["encode"] += t6 - t5 - overhead
    rec.flush()
    eng.rec.close()
    for p in tmp.iterdir():
        p.unlink()
    tmp.rmdir()
    w = {p: v / ticks / 1e3 for p, v in world.items()}  # us per tick
    a = {p: v / ticks / n / 1e3 for p, v in agent.items()}  # us per agent per tick
    return {
        "n": n,
        "sensing": "unlimited" if neighbours is None else f"~{neighbours} others",
        "range": sens.range,
        "contacts": contacts / ticks / n,
        "world_us": w,
        "world_total_us": sum(w.values()),
        "agent_us": a,
        "agent_total_us": sum(a.values()),
    }


def best_us(f, number: int = 5, repeat: int = 40) -> float:
    """us per call of f, the best of `repeat` rounds (warm caches: the constants, not a tick's)."""
    return min(timeit.repeat(f, number=number, repeat=repeat)) / number * 1e6


def scaling(sizes: list[int], neighbours: int, contacts: list[int]) -> dict:
    """The constants of the cost model, warm: who senses whom at N agents spread over a disc
    with about `neighbours` in sight, every pair against the grid (its pairs, and the (N, N)
    matrices made from them), and encoding every frame; an agent's decoding and nearest
    choice of a frame of K contacts."""
    # lazy: the grid is newer than the checkouts --tree may measure (they run measure() only)
    from swarm.world.sensing import sensing_grid, sensing_pairs

    rs = np.random.default_rng(1)
    world = []
    for n in sizes:
        r, t = 30.0 * np.sqrt(rs.random(n)), rs.uniform(0, 2 * np.pi, n)
        x, y, g = r * np.cos(t), r * np.sin(t), rs.uniform(-np.pi, np.pi, n)
        p = np.ones(n, dtype=bool)
        sr = 30.0 * np.sqrt(neighbours / n)
        pairs = sensing_pairs(x, y, g, p, sr, None)
        lead, hops = np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)
        head = (1, 0.0, range(n), np.arange(1, n + 1), g, x, y, lead)  # tick, time, rows, ids, heading, target, leaders
        mats = sensing_grid(x, y, g, p, sr, None)
        full = sensing_matrix(x, y, g, p, None, None)
        world.append(
            {
                "n": n,
                "in_sight": len(pairs[0]) / n,
                "every_pair_range_us": best_us(partial(sensing_matrix, x, y, g, p, sr, None)),
                "grid_pairs_us": best_us(partial(sensing_pairs, x, y, g, p, sr, None)),
                "grid_matrices_us": best_us(partial(sensing_grid, x, y, g, p, sr, None)),
                "every_pair_unlimited_us": best_us(partial(sensing_matrix, x, y, g, p, None, None)),
                "encode_rows_range_us": best_us(partial(wire.encode_sense_rows, *head, *mats, hops)),
                "encode_pairs_range_us": best_us(partial(wire.encode_sense_pairs, *head, *pairs, hops)),
                "encode_rows_unlimited_us": best_us(partial(wire.encode_sense_rows, *head, *full, hops), repeat=10),
            }
        )
    agent = []
    for k in contacts:
        cs = tuple(Contact(j, 0.1 * j, 0.2, 1.0 + (j * 7919) % k, 0) for j in range(k))
        buf = wire.encode_sense(SensorFrame(3, 0.03, 1, 0.1, cs, None))
        agent.append(
            {
                "k": k,
                "decode_us": best_us(partial(wire.decode_sense, buf), number=50),
                "nearest_us": best_us(partial(nearest, cs), number=50),
            }
        )
    return {"world": world, "agent": agent}


def print_scaling(sc: dict) -> None:
    w = sc["world"]
    keys = [k for k in w[0] if k not in ("n", "in_sight")]
    print(f"{'N':>5} {'in sight':>8} " + " ".join(f"{k:>24}" for k in keys))
    for r in w:
        print(f"{r['n']:>5} {r['in_sight']:8.1f} " + " ".join(f"{r[k]:24.1f}" for k in keys))
    print(f"{'K':>5} {'decode_us':>10} {'nearest_us':>10}")
    for r in sc["agent"]:
        print(f"{r['k']:>5} {r['decode_us']:10.2f} {r['nearest_us']:10.2f}")


def commit_of(tree: Path) -> str:
    try:
        return subprocess.run(
            ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def table(rows: list[dict], label: str = "") -> None:
    head = f"{'':>7}{'N':>4} | {'sensing':>10} | {'contacts':>8} | world us/tick: " + " ".join(
        f"{p:>8}" for p in WORLD_PARTS
    )
    head += f" {'total':>8} | agent us/tick: " + " ".join(f"{p:>6}" for p in AGENT_PARTS) + f" {'total':>6}"
    print(head)
    for r in rows:
        w, a = r["world_us"], r["agent_us"]
        print(
            f"{r.get('label', label):>7}{r['n']:>4} | {r['sensing']:>10} | {r['contacts']:8.1f} | {'':14}"
            + " ".join(f"{w[p]:8.1f}" for p in WORLD_PARTS)
            + f" {r['world_total_us']:8.1f} | {'':14}"
            + " ".join(f"{a[p]:6.1f}" for p in AGENT_PARTS)
            + f" {r['agent_total_us']:6.1f}"
        )


def run_here(a: argparse.Namespace) -> list[dict]:
    rows = []
    for n in (int(x) for x in a.sizes.split(",")):
        for nb in (None, a.neighbours):
            rows.append(measure(n, nb, a.ticks, a.selection, pairs=a.pairs))
    return rows


def compare(a: argparse.Namespace) -> list[dict]:
    """This script on OLD_TREE and on this checkout, interleaved, `reps` times each."""
    old = Path(a.compare).resolve()
    base = [sys.executable, str(Path(__file__).resolve()), "--sizes", a.sizes, "--ticks", str(a.ticks)]
    base += ["--neighbours", str(a.neighbours), "--selection", a.selection, "--quiet"]
    after = ["--pairs"] if a.pairs else []
    out: list[dict] = []
    for rep in range(a.reps):
        for label, tree, more in (("before", old, []), ("after", REPO, after)):
            with tempfile.NamedTemporaryFile(suffix=".json") as f:
                subprocess.run([*base, *more, "--tree", str(tree), "--json", f.name], check=True)
                for r in json.loads(Path(f.name).read_text())["rows"]:
                    out.append({**r, "label": label, "rep": rep, "commit": commit_of(tree)})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="6,100")
    ap.add_argument("--ticks", type=int, default=400)
    ap.add_argument("--neighbours", type=int, default=8)
    ap.add_argument("--selection", default="nearest", help="the followers' selection rule (default nearest)")
    ap.add_argument("--tree", type=Path, default=REPO, help="the checkout whose swarm is measured")
    ap.add_argument("--compare", help="an older checkout: measure it and this one, interleaved")
    ap.add_argument("--reps", type=int, default=3, help="with --compare: repetitions of each")
    ap.add_argument("--json", type=Path, help="write the rows to this JSON file")
    ap.add_argument("--quiet", action="store_true", help="no table (with --json)")
    ap.add_argument(
        "--pairs", action="store_true", help="the world encodes from sensed_pairs where the grid is used (as it does)"
    )
    ap.add_argument("--scaling", action="store_true", help="the cost model's constants against N and K instead")
    ap.add_argument("--scaling-sizes", default="50,100,200,500,1000")
    ap.add_argument("--contacts", default="0,5,10,20,50,99")
    a = ap.parse_args(argv)
    if a.scaling:
        sizes, ks = [int(v) for v in a.scaling_sizes.split(",")], [int(v) for v in a.contacts.split(",")]
        sc = scaling(sizes, a.neighbours, ks)
        if a.json:
            a.json.write_text(json.dumps({"commit": commit_of(TREE), "date": time.strftime("%Y-%m-%d"), **sc}))
        print_scaling(sc)
        return ExitCode.OK
    rows = compare(a) if a.compare else run_here(a)
    meta = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "commit": commit_of(REPO) if a.compare else commit_of(TREE),
        "machine": f"{platform.node()}, {os.cpu_count()} cores, {platform.processor() or platform.machine()}",
        "python": platform.python_version(),
        "swarm": str(Path(swarm.__file__).parents[1]),
    }
    if a.json:
        a.json.write_text(json.dumps({**meta, "rows": rows}, indent=1))
    if not a.quiet:
        print(f"{meta['date']}, commit {meta['commit']}, {meta['machine']}, Python {meta['python']}")
        table(rows, "" if a.compare else commit_of(TREE))
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
