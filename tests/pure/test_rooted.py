"""The rooted selection rule (issue "Resilience", part 2): pure and in-process tiers."""

import json
from pathlib import Path

import numpy as np
import pytest

from swarm.agents.brain import AgentBrain
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.graph import analyse
from swarm.contracts.scenario import load_scenario
from swarm.offline.sim import run_sim

ROOTED = Path(__file__).resolve().parents[2] / "scenarios" / "rooted.toml"


def _final_graph(result):
    a = result.recorder.arrays()
    out = {int(i): (int(o) if o >= 0 else None) for i, o in zip(a["ids"], a["out"][-1])}
    leaders = {int(i) for i, r in zip(a["ids"], a["role"]) if r == "leader"}
    return analyse(out, leaders)


@pytest.mark.slow
def test_nearest_selection_forms_a_follower_only_cycle_that_the_graph_flags():
    s = load_scenario(ROOTED)
    s = s.model_copy(update={"sensing": s.sensing.model_copy(update={"selection": "nearest"})})
    g = _final_graph(run_sim(s, duration=5.0))
    assert [2, 5] in g["cycles"], g
    assert {2, 5} <= set(g["unrooted"])


@pytest.mark.slow  # a whole run (the session's: conftest.shipped_sim)
def test_rooted_selection_roots_every_follower_and_converges(shipped_sim):
    """rooted.toml's whole `swarm sim` run, shared with tests/pure/test_cli_offline.py (which
    checks it converges too) and the lockstep tests."""
    res, out = shipped_sim("rooted")
    assert res.exit_code == 0, res.output
    with np.load(out / "trajectory.npz") as z:
        a = {k: z[k] for k in ("t", "ids", "role", "out")}
    assert len(a["t"]) == load_scenario(ROOTED).run.ticks + 1  # the whole run
    leaders = {int(i) for i, r in zip(a["ids"], a["role"]) if r == "leader"}
    g = analyse({int(i): (int(o) if o >= 0 else None) for i, o in zip(a["ids"], a["out"][-1])}, leaders)
    assert g["cycles"] == [] and g["unrooted"] == []
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"], summary["agents"]
    # Once rooted, nobody ever sits in a follower-only cycle: check every 100th tick.
    for k in range(0, len(a["t"]), 100):
        out_k = {int(i): (int(o) if o >= 0 else None) for i, o in zip(a["ids"], a["out"][k])}
        assert analyse(out_k, {1})["cycles"] == [], (k, out_k)


def _brain():
    s = load_scenario(ROOTED)
    return AgentBrain(BrainConf.from_scenario(s, 2))


def _frame(tick, *contacts):
    return SensorFrame(tick, tick * 0.01, 2, 0.0, tuple(contacts), None)


def test_rooted_switches_only_to_shallower_agents():
    b = _brain()
    d = b.decide(_frame(0, Contact(1, 0.0, 0.0, 50.0, 0)))
    assert d.out == 1 and d.hops == 1
    # A nearer agent with as many hops (could be a descendant, or swapping with a sibling): no.
    d = b.decide(_frame(1, Contact(1, 0.0, 0.0, 50.0, 0), Contact(5, 0.0, 0.0, 5.0, 1)))
    assert d.out == 1
    d = b.decide(_frame(2, Contact(1, 0.0, 0.0, 50.0, 0), Contact(5, 0.0, 0.0, 5.0, 2)))
    assert d.out == 1


def test_rooted_after_losing_its_leader_ignores_former_descendants_then_loiters():
    b = _brain()
    b.decide(_frame(0, Contact(1, 0.0, 0.0, 50.0, 0)))
    # Leader gone; agent 5 still advertises 2 hops (it followed us): not a candidate.
    d = b.decide(_frame(1, Contact(5, 0.0, 0.0, 5.0, 2)))
    assert d.out is None and d.phase == "lost" and d.hops is None
    assert abs(d.u) == b.gains.c2  # loiter circle of radius v / C2
    # Once stale advertisements have had max_hops ticks to drain, any rooted agent will do.
    for k in range(2, 2 + b.max_hops):
        d = b.decide(_frame(k, Contact(5, 0.0, 0.0, 5.0, 3)))
    assert d.out == 5 and d.hops == 4


def test_unrooted_contacts_are_never_chosen():
    b = _brain()
    d = b.decide(_frame(0, Contact(3, 0.0, 0.0, 1.0, -1), Contact(4, 0.0, 0.0, 2.0, -1)))
    assert d.out is None and d.phase == "lost"
    assert np.isfinite(d.u)
