"""`swarm up`'s progress line, from the latest ground truth the launcher heard.

Each live agent's radial error: its distance to the target against the radius expected
from its path to a leader (swarm/contracts/orbits.py), or none without a path; then the
line's text, agent by agent for a small swarm, summed up (median, worst, how many have no
leader) for a large one. Agents added at run time have no spec here and are skipped.
"""

from __future__ import annotations

import math

from swarm.contracts import wire
from swarm.contracts.orbits import expected_radius, root_of
from swarm.contracts.scenario import Scenario

PROGRESS_AGENTS = 12  # more agents than this: the progress line sums them up


def truth_progress(buf: bytes | None, s: Scenario) -> dict | None:
    """Figures for the progress line from a ground-truth message (None: none, or unreadable)."""
    if buf is None:
        return None
    try:
        tick, t, recs = wire.decode_truth(buf)
    except wire.WireError:
        return None
    known = set(s.ids)  # agents added at run time (swarm spawn) have no spec here: skipped
    recs = [r for r in recs if int(r["id"]) in known]
    leaders = {a.id for a in s.agents if a.role == "leader"}
    alive = {int(r["id"]) for r in recs if r["state"] == 0}
    out = {int(r["id"]): (int(r["out"]) if r["out"] >= 0 else None) for r in recs}
    errs = {}
    for r in recs:
        aid = int(r["id"])
        if aid not in alive:
            continue
        root, _ = root_of(aid, out, leaders & alive)
        if root is None:
            errs[aid] = None
            continue
        L, me = s.agent(root), s.agent(aid)
        R = expected_radius(me.speed, L.speed, L.orbit_radius)
        errs[aid] = abs(math.hypot(r["x"] - s.target.x, r["y"] - s.target.y) - R) / R
    return {"tick": tick, "time": t, "errors": errs, "dropped": sorted(set(out) - alive)}


def progress_errors(p: dict) -> str:
    """The progress line's radial errors: one per agent for a small swarm; for a large one
    the median, the worst and how many have no leader to follow ("-" per agent)."""
    errs, dropped = p["errors"], p["dropped"]
    if len(errs) + len(dropped) <= PROGRESS_AGENTS:
        text = " ".join(f"{i}:{'-' if e is None else f'{100 * e:.1f}%'}" for i, e in sorted(errs.items()))
        return f"radial error {text}" + (f"  dropped {dropped}" if dropped else "")
    rooted = sorted((e, i) for i, e in errs.items() if e is not None)
    text = (f"radial error median {100 * rooted[len(rooted) // 2][0]:.1f}%, worst {100 * rooted[-1][0]:.1f}% "
            f"(agent {rooted[-1][1]})" if rooted else "radial error -")
    return (f"{text}; {len(errs) - len(rooted)} of {len(errs)} live agents without a leader"
            + (f"; {len(dropped)} dropped" if dropped else ""))
