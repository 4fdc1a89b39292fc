"""An agent's per-frame work and the world's per-command decoding, warm and with cold caches
(a benchmark, not a test).

    python benchmarks/bench_cold.py [--scenario scenarios/case2.toml] [--frames 3000] [--reps 2]

In a run, seven processes or more take turns on two cores, and each starts its turn with
caches the others have filled: a warm loop says what the code costs at best, not what a
tick pays. This replays one follower's frames of a `swarm sim` of the scenario through
the agent's path (wire.decode_sense, AgentBrain.decide, wire.encode_cmd_fields), once warm
and once with an 8 MB buffer written between frames (past this machine's L2 and most of
its L3), and times each part alone the cold way; and the same for the world's decoding of
a command (wire.decode_cmd). Medians in microseconds, "nothing" being the harness's own
cost (a call that does nothing, timed the same way).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # the repository's swarm, not an installed copy

from swarm.agents.brain import AgentBrain  # noqa: E402
from swarm.agents.selection import nearest  # noqa: E402
from swarm.contracts import wire  # noqa: E402
from swarm.contracts.brain_config import BrainConf  # noqa: E402
from swarm.contracts.fastpath import path as wire_path  # noqa: E402
from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.contracts.vocabulary import ExitCode, FollowState  # noqa: E402
from swarm.world.engine import Engine  # noqa: E402

JUNK = np.zeros(8 << 20, np.uint8)  # written between calls: evicts the caches


def timed(fn: Callable[[int], object], count: int, reps: int, cold: bool) -> float:
    """Median us of fn(i) for i in range(count), reps times, caches evicted before each call if cold."""
    ts = []
    for _ in range(reps):
        for i in range(count):
            if cold:
                JUNK.__iadd__(1)
            t0 = time.perf_counter_ns()
            fn(i)
            ts.append(time.perf_counter_ns() - t0)
    return statistics.median(ts) / 1e3


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=REPO / "scenarios" / "case2.toml")
    ap.add_argument("--frames", type=int, default=3000, help="ticks simulated (one follower's frames replayed)")
    ap.add_argument("--reps", type=int, default=2)
    a = ap.parse_args(argv)
    sc = load_scenario(a.scenario)
    followers = [s.id for s in sc.agents if s.role == "follower"]
    if not followers:
        ap.error(f"{a.scenario}: no follower to replay")
    eng = Engine(sc, a.frames)
    brains = {s.id: AgentBrain(BrainConf.from_scenario(sc, s.id)) for s in sc.agents}
    who = followers[len(followers) // 2]
    frames: list[bytes] = []
    for k in range(a.frames):
        for aid, f in eng.frames().items():
            d = brains[aid].decide(f)
            eng.command(aid, k, d.u, d.out, d.hops)
            if aid == who:
                frames.append(wire.encode_sense(f))
        eng.end_tick()
    spec = sc.agent(who)
    decoded = [wire.decode_sense(b) for b in frames]
    keep = FollowState.KEEP
    cmds = [wire.encode_cmd_fields(who, k, 0.1 * (k % 7), 2, "track", 1, 12345, keep) for k in range(len(frames))]
    count = len(frames)

    def whole(brain: AgentBrain) -> Callable[[int], object]:
        def f(i: int) -> bytes:
            fr = wire.decode_sense(frames[i])
            d = brain.decide(fr)
            return wire.encode_cmd_fields(who, fr.tick, d.u, d.out, d.phase, d.hops, 7, d.follow)  # as agents/node.py

        return f

    def brain() -> AgentBrain:
        return AgentBrain(BrainConf.from_scenario(sc, spec.id))

    print(f"{a.scenario.name}, agent {who}, {count} frames, {sc.sensing.selection} selection; wire path: {wire_path}")
    rows = [
        ("the agent's path (decode, decide, encode), warm", timed(whole(brain()), count, a.reps, False)),
        ("the agent's path, cold", timed(whole(brain()), count, a.reps, True)),
    ]
    b = brain()
    rows += [
        ("  decode alone, cold", timed(lambda i: wire.decode_sense(frames[i]), count, a.reps, True)),
        ("  decide alone, cold", timed(lambda i: b.decide(decoded[i]), count, a.reps, True)),
        ("    nearest contact alone, cold", timed(lambda i: nearest(decoded[i].contacts), count, a.reps, True)),
        (
            "  encode the command alone, cold",
            timed(lambda i: wire.encode_cmd_fields(who, i, 0.1, 2, "track", 1, 7, keep), count, a.reps, True),
        ),
        ("the world's decode of a command, cold", timed(lambda i: wire.decode_cmd(cmds[i]), count, a.reps, True)),
        ("nothing (the harness), cold", timed(lambda i: None, count, a.reps, True)),
    ]
    for label, us in rows:
        print(f"{label:52s} {us:7.1f} us")
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
