"""How the CPU cost of one lockstep tick grows with N and with the sensing range, without
zenoh (a benchmark, not a test).

    python benchmarks/bench_tick.py [--sizes 6,20,50,100,200] [--ticks 300] [--neighbours 8]

For bench_runtime.py's ring scenario with N agents, in this one process, the code that runs
each tick in `swarm up` (its Python, not the messaging):

- world: the sensing matrices, every frame encoded (wire.encode_sense_rows), every command
  decoded and latched (Engine.command), the tick recorded in memory and integrated;
- agents: each agent's frame decoded, its decision (selection, law) and its command
  encoded, summed over the agents;

with unlimited sensing and with a range under which each agent senses about --neighbours
others at the start; "contacts" is the mean a frame carried. Hot caches, one core: in a
real run 2N processes share two cores and every figure is several times larger, so read
the growth, not the absolute values. Asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_runtime import scenario_toml  # noqa: E402

from swarm.agents.brain import AgentBrain  # noqa: E402
from swarm.contracts import wire  # noqa: E402
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.scenario import parse_scenario  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.world.engine import Engine  # noqa: E402


def measure(n: int, neighbours: int | None, ticks: int) -> dict:
    s = parse_scenario(tomllib.loads(scenario_toml(n, neighbours, ticks=ticks + 50)))
    eng = Engine(s, ticks + 100)
    brains = {a.id: AgentBrain(BrainConf.from_scenario(s, a.id)) for a in s.agents}
    world_s = agents_s = 0.0
    contacts = 0
    for k in range(ticks + 50):
        t0 = time.perf_counter()
        c = eng.core
        eng.mark_frames()
        sensed, bearing, rng = c.sensing()
        active = c.active_ids()
        frames = wire.encode_sense_rows(
            c.tick,
            c.time,
            [c.index[a] for a in active],
            c.ids,
            c.heading,
            c.target[0] - c.x,
            c.target[1] - c.y,
            c.is_leader,
            sensed,
            bearing,
            rng,
            c.hops,
        )
        t1 = time.perf_counter()
        cmds = []
        for aid, buf in zip(active, frames):
            f = wire.decode_sense(buf)
            d = brains[aid].decide(f)
            cmds.append(wire.encode_cmd_fields(aid, f.tick, d.u, d.out, d.phase, d.hops, 0))
            contacts += len(f.contacts) if k >= 50 else 0
        t2 = time.perf_counter()
        for buf in cmds:
            cm = wire.decode_cmd(buf)
            eng.command(cm.agent, cm.tick, cm.u, cm.out, cm.hops)
        eng.end_tick()
        t3 = time.perf_counter()
        if k >= 50:  # after a warm-up
            world_s += (t1 - t0) + (t3 - t2)
            agents_s += t2 - t1
    return {
        "n": n,
        "contacts": contacts / ticks / n,
        "world_ms": 1e3 * world_s / ticks,
        "agent_us": 1e6 * agents_s / ticks / n,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="6,20,50,100,200")
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--neighbours", type=int, default=8)
    a = ap.parse_args(argv)
    print(f"{'N':>4} | {'sensing':>9} | {'contacts':>8} | {'world ms/tick':>13} | {'per agent us/tick':>17}")
    print("-" * 64)
    for n in (int(x) for x in a.sizes.split(",")):
        for nb in (None, a.neighbours):
            r = measure(n, nb, a.ticks)
            print(
                f"{n:>4} | {'unlimited' if nb is None else f'~{nb} others':>9} | {r['contacts']:8.1f} | "
                f"{r['world_ms']:13.3f} | {r['agent_us']:17.1f}"
            )
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
