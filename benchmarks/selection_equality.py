"""Selection equality: does a change to the sticky selection (agents/selection.py and the
modules around it) leave every choice, trajectory, event and switch reason as it was, to
the bit?

For every scenario in scenarios/*.toml and for N random range-limited swarms (range 40-60 m,
every other one with a field of view; swarm/study/swarms.random_swarm, the generator of
`swarm study swarms`), the sha256 of `swarm.simulate(...)`'s x, y, heading, u and out arrays
and of the events' (tick, agent, kind, reason, from, to). The random swarms also run through
the batch engine (`simulate(..., batch=True)`, what `swarm study` uses).

    .venv/bin/python benchmarks/selection_equality.py --save /tmp/before.json
    ... change the code ...
    .venv/bin/python benchmarks/selection_equality.py --against /tmp/before.json

--against prints "equal: N/N" and exits 1 on any difference (naming the runs that differ).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def digest(res) -> str:
    h = hashlib.sha256()
    for name in ("x", "y", "heading", "u", "out"):
        a = getattr(res, name)
        h.update(name.encode())
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    for ev in res.summary.get("events", []) or []:
        e = dict(ev._data) if hasattr(ev, "_data") else dict(ev)
        key = [e.get(k) for k in ("tick", "agent", "kind", "reason", "from", "to")]
        h.update(json.dumps(key, default=str).encode())
    return h.hexdigest()


def random_swarms(n: int):
    from swarm.study.swarms import SwarmSetting, random_swarm

    for k in range(n):
        rng = 40.0 + 20.0 * ((k * 7) % 11) / 10.0  # 40..60 m
        fov = 2 * math.pi if k % 2 == 0 else math.radians(200 + 10 * (k % 7))
        setting = SwarmSetting(n=6 + k % 3, leaders=1 + k % 2, range=rng, fov=fov, duration=40.0, dt=0.05)
        yield f"random-{k}", random_swarm(setting, 1000 + k)


def _run(job: tuple[str, str | int, bool]) -> tuple[str, str, float]:
    import swarm

    name, what, batch = job
    t0 = time.perf_counter()
    s = dict(random_swarms(int(what) + 1))[f"random-{what}"] if isinstance(what, int) else Path(what)
    return name, digest(swarm.simulate(s, batch=batch)), time.perf_counter() - t0


def digests(n_random: int, verbose: bool, jobs: int) -> dict[str, str]:
    todo: list[tuple[str, str | int, bool]] = [
        (p.stem, str(p), False) for p in sorted((ROOT / "scenarios").glob("*.toml"))
    ]
    for k in range(n_random):
        todo += [(f"random-{k}", k, False), (f"random-{k}-batch", k, True)]
    out: dict[str, str] = {}
    with multiprocessing.get_context("spawn").Pool(jobs) as pool:
        for name, d, wall in pool.imap_unordered(_run, todo):
            out[name] = d
            if verbose:
                print(f"{name}: {d[:12]} ({wall:.1f} s)", flush=True)
    return dict(sorted(out.items()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--save", type=Path, help="write the digests to this JSON file")
    ap.add_argument("--against", type=Path, help="compare with the digests in this JSON file")
    ap.add_argument("--random", type=int, default=50, help="random swarms (default 50)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("-q", "--quiet", action="store_true")
    a = ap.parse_args()
    got = digests(a.random, not a.quiet, a.jobs)
    if a.save:
        a.save.write_text(json.dumps(got, indent=1, sort_keys=True))
    if a.against:
        want = json.loads(a.against.read_text())
        names = sorted(set(want) | set(got))
        diff = [k for k in names if want.get(k) != got.get(k)]
        print(f"equal: {len(names) - len(diff)}/{len(names)}")
        for k in diff:
            print(f"  differs: {k}")
        return 1 if diff else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
