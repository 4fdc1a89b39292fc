"""The law API (docs/guides/writing-a-law.md): one Observation in, a turn rate out, for
followers and leaders; laws named in [law] and checked at load; the scenario's directory
on the import path; the join reply's `law`; the batch engine's refusal."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import uuid
from pathlib import Path
from types import MappingProxyType

import helpers_law
import numpy as np
import pytest
from fakes import FakeSession
from test_shells import RUN, claim, open_world
from typer.testing import CliRunner

from swarm.agents.brain import AgentBrain
from swarm.agents.joining import AgentExit
from swarm.agents.laws import bearing, bearing_law, loiter, search
from swarm.agents.leader import on_orbit_command
from swarm.agents.node import AgentNode
from swarm.cli.main import app
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.laws import ENV_LAW_PATH, law_dirs, with_law_path
from swarm.contracts.observation import Observation, Search
from swarm.contracts.scenario import ScenarioError, load_scenario, parse_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.offline.batch import refusal
from swarm.offline.sim import run_sim
from swarm.world.sensing import Contact, SensorFrame


@pytest.fixture
def law_module(monkeypatch):
    """tests/support/helpers_law.py, importable as `helpers_law` (its laws resolve by name)."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "support"))
    return helpers_law


def _brain(base, aid, law):
    base["law"] = law
    s = parse_scenario(base)
    return AgentBrain(BrainConf.from_scenario(s, aid)), s


# -- what a law is given --------------------------------------------------------------------------


def test_a_follower_law_gets_one_observation(base, law_module):
    base["agents"][1]["max_turn_rate"] = 2.0
    brain, s = _brain(base, 2, {"follower": "helpers_law:echo_obs", "params": {"k": 2.5}})
    brain.last_u = 0.125
    contacts = (Contact(1, 1.1, 0.9, 8.0, 0), Contact(3, -0.5, 2.0, 1.0, -1))
    d = brain.decide(SensorFrame(7, 0.35, 2, 0.2, contacts))
    obs = brain.state["obs"]
    assert isinstance(obs, Observation) and d.out == 1 and d.phase == "track"
    assert (obs.id, obs.role, obs.tick, obs.time, obs.dt) == (2, "follower", 7, 0.35, 0.05)
    assert (obs.speed, obs.heading, obs.max_turn_rate, obs.last_u) == (1.5, 0.2, 2.0, 0.125)
    assert obs.contacts == contacts and obs.out == contacts[0]  # pinned: follow = 1
    assert obs.target is None and obs.target_range is None and obs.target_bearing is None
    assert (obs.c1, obs.c2) == (s.gains.c1, s.gains.c2) and dict(obs.params) == {"k": 2.5}
    assert obs.state is brain.state
    with pytest.raises(TypeError):
        obs.params["k"] = 1.0  # read-only


def test_a_leader_law_gets_the_target(base, law_module):
    base["agents"][0]["direction"] = "cw"
    brain, _ = _brain(base, 1, {"leader": "helpers_law:echo_obs"})
    d = brain.decide(SensorFrame(0, 0.0, 1, 1.0, (Contact(2, 0.0, 0.0, 3.0),), (-3.0, 4.0)))
    obs = brain.state["obs"]
    assert (obs.role, obs.out, obs.orbit_radius, obs.direction) == ("leader", None, 2.0, -1)
    assert obs.target == (-3.0, 4.0) and obs.target_range == 5.0
    assert obs.target_bearing == math.atan2(4.0, -3.0) and len(obs.contacts) == 1
    assert d.u == 0.0 and d.phase == "orbit" and d.hops == 0  # a law that sets no phase: "orbit"


def test_state_is_kept_between_calls_and_new_with_a_new_brain(base, law_module):
    frame = SensorFrame(0, 0.0, 1, 1.0, (), (-2.0, 0.0))
    brain, s = _brain(base, 1, {"leader": "helpers_law:orbit_rate_leader", "params": {"rate": 0.3}})
    us = [brain.decide(frame._replace(tick=k)).u for k in range(3)]
    assert us == [0.3] * 3 and brain.state == {"calls": 3}
    fresh = AgentBrain(BrainConf.from_scenario(s, 1), max_hops=3)
    assert fresh.state == {}


def test_the_built_in_follower_law_on_an_observation_is_the_formula(base):
    brain, s = _brain(base, 2, {})
    c = Contact(1, 1.1, 0.9, 8.0)
    obs = brain._observe(SensorFrame(0, 0.0, 2, 0.2, (c,)), c, None)
    assert bearing(obs) == bearing_law(0.2, 0.9, 1.1, s.gains.c1, s.gains.c2)
    lost = obs._replace(out=None, last_u=-0.4)
    assert bearing(lost) == loiter(lost) == -s.gains.c2  # no search circle: loiter
    circle = Search(-10.0, 0.0, 4.0, 1)  # home 10 m behind it (heading 0.2)
    searching = lost._replace(search=circle)
    assert (
        bearing(searching)
        == search(searching)
        == on_orbit_command(10.0, 0.0, 0.2, searching.speed, 4.0, 1, searching.max_turn_rate)
    )


# -- through the engine ---------------------------------------------------------------------------


def test_a_custom_leader_law_is_used_by_run_sim(base, law_module):
    base["law"] = {"leader": "helpers_law:orbit_rate_leader", "params": {"rate": 0.3}}
    a = run_sim(parse_scenario(base), duration=1.0).recorder.arrays()
    leader = a["role"] == "leader"
    assert np.all(a["u"][:-1, leader] == 0.3)  # the CC planner would start at v / R = 0.5
    follower = run_sim(parse_scenario({k: v for k, v in base.items() if k != "law"}), duration=1.0)
    np.testing.assert_array_equal(follower.recorder.arrays()["u"][0, ~leader], a["u"][0, ~leader])


def test_a_custom_follower_law_is_used_by_run_sim(base, law_module):
    base["law"] = {"follower": "helpers_law:stateful_follower", "params": {"k": 0.7}}
    a = run_sim(parse_scenario(base), duration=0.5).recorder.arrays()
    x, y, g = a["x"][0], a["y"][0], a["heading"][0]
    for i, j in ((1, 0), (2, 1)):  # fixed graph 2 -> 1, 3 -> 2
        lam = math.atan2(y[j] - y[i], x[j] - x[i])
        assert a["u"][0, i] == pytest.approx(0.7 * math.sin(lam - g[i]), abs=1e-12)


# -- checked at load ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, fragments",
    [
        (
            {"law": {"follower": "helpers_law:constant_law"}},
            ["law.follower", "does not take one argument (obs", "goes in [gains] law"],
        ),
        ({"law": {"leader": "helpers_law:two_arg_law"}}, ["law.leader", "leader law", "does not take one argument"]),
        ({"law": {"leader": "helpers_law:missing"}}, ["law.leader", "has no function 'missing'"]),
        ({"law": {"leader": "nope"}}, ["law.leader", "unknown leader law 'nope'", "['cc']"]),
        ({"law": {"follower": "no_such_module_xyz:f"}}, ["law.follower", "cannot import module 'no_such_module_xyz'"]),
        (
            {"gains": {"c1": 1.0, "c2": 0.5, "law": "helpers_law:orbit_rate_leader"}},
            ["gains.law", "does not take (g_i, g_j, lambda_ij, c1, c2)", "goes in [law] follower"],
        ),
        (
            {
                "gains": {"c1": 1.0, "c2": 0.5, "law": "helpers_law:constant_law"},
                "law": {"follower": "helpers_law:stateful_follower"},
            },
            ["law.follower", "named twice", "keep one"],
        ),
        ({"law": {"params": {"k": "x"}}}, ["law.params.k"]),
        ({"law": {"colour": "red"}}, ["law.colour", "unknown key"]),
    ],
)
def test_a_bad_law_names_the_file_and_the_field(base, write_toml, law_module, change, fragments):
    base.update(change)
    path = write_toml(base)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: invalid scenario")
    for frag in fragments:
        assert frag in msg, msg


def test_law_names_are_what_swarm_up_trusts(base, law_module):
    assert parse_scenario(base).law_names == ["bearing", "cc"]
    base["law"] = {"leader": "helpers_law:orbit_rate_leader"}
    assert parse_scenario(base).law_names == ["bearing", "helpers_law:orbit_rate_leader"]


# -- the scenario's directory is on the import path -----------------------------------------------


def _law_next_to_scenario(tmp_path, write_toml, base, source: str, where: str):
    mod = f"dirlaw_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{mod}.py").write_text(source)
    assert importlib.util.find_spec(mod) is None  # not importable from here before
    base["law"] = {where: f"{mod}:law"}
    return write_toml(base), mod


@pytest.mark.slow
def test_check_and_sim_import_a_law_next_to_the_scenario(tmp_path, write_toml, base, monkeypatch):
    monkeypatch.setattr(sys, "path", list(sys.path))  # the scenario's dir is appended: undone after
    path, mod = _law_next_to_scenario(tmp_path, write_toml, base, "def law(obs):\n    return 0.2\n", "leader")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == 0, res.output
    assert f"leader={mod}:law" in res.stdout
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sim", str(path), "--out", str(out), "--no-plots", "--duration", "0.5"])
    assert res.exit_code == 0, res.output
    with np.load(out / "trajectory.npz") as z:
        assert np.all(z["u"][:-1, 0] == 0.2)


@pytest.mark.slow
def test_a_raising_law_under_swarm_sim_is_a_crash_event_and_exit_4(tmp_path, write_toml, base, monkeypatch):
    """As under swarm up (tests/process/test_supervision_runtime.py): no traceback, a crash event with
    its cause, the agent dropped, the results written, one line, exit 4."""
    monkeypatch.setattr(sys, "path", list(sys.path))
    source = "def law(obs):\n    if obs.tick >= 3:\n        raise RuntimeError('gave up')\n    return 0.1\n"
    path, _ = _law_next_to_scenario(tmp_path, write_toml, base, source, "follower")
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sim", str(path), "--out", str(out), "--no-plots", "--duration", "0.5"])
    assert res.exit_code == 4, res.output
    assert "Traceback" not in res.output
    (line,) = res.stderr.strip().splitlines()
    assert "agent" in line and "RuntimeError: gave up" in line and str(out) in line
    summ = json.loads((out / "summary.json").read_text())
    crashes = [e for e in summ["events"] if e["kind"] == "crash"]
    assert crashes and all(e["cause"] == "RuntimeError: gave up" and e["tick"] == 3 for e in crashes)
    assert not summ["converged"] and (out / "trajectory.npz").exists()
    assert {e["agent"] for e in summ["events"] if e["kind"] == "drop"} == {e["agent"] for e in crashes}


def test_law_path_for_agent_processes(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_LAW_PATH, "/a")
    assert law_dirs([tmp_path]) == [str(tmp_path), "/a"]
    assert with_law_path([tmp_path, "/a"]).split(":") == [str(tmp_path), "/a"]


# -- the join reply, trust, the batch engine ------------------------------------------------------


def test_the_join_reply_carries_the_laws(base, law_module):
    base["law"] = {"leader": "helpers_law:orbit_rate_leader", "params": {"rate": 0.25}}
    s = parse_scenario(base)
    for aid, names in ((1, ["helpers_law:orbit_rate_leader"]), (2, ["bearing"])):
        conf = BrainConf.from_scenario(s, aid)
        back = BrainConf.from_json(json.loads(json.dumps(conf.to_json())))
        assert back == conf and back.law.params == {"rate": 0.25} and back.law_names() == names
    d = json.loads(json.dumps(BrainConf.from_scenario(s, 2).to_json()))
    del d["law"]  # a world that sends none: the built-in laws
    assert BrainConf.from_json(d).law_names() == ["bearing"]
    for bad, field in (
        ({"leader": 3}, "law.leader"),
        ({"params": {"k": float("nan")}}, "law.params.k"),
        ({"params": {"k": True}}, "law.params.k"),
        ([], "law:"),
    ):
        with pytest.raises(ValueError, match=field.replace(".", r"\.")):
            BrainConf.from_json({**d, "law": bad})


def test_an_untrusted_leader_law_is_refused_without_importing_it(tmp_path, monkeypatch):
    (tmp_path / "evil_leader.py").write_text("def law(obs):\n    return 0.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("SWARM_TRUSTED_LAWS", raising=False)
    world, _ = open_world()
    reply = claim(world, 1)
    brain = json.loads(json.dumps(reply["brain"]))
    brain["law"]["leader"] = "evil_leader:law"
    with pytest.raises(AgentExit) as exc:
        AgentNode(FakeSession(), RUN, 1, {**reply, "brain": brain}, wait_world=False)
    assert exc.value.code == ExitCode.REFUSED and "--trust-law evil_leader:law" in exc.value.message
    assert "evil_leader" not in sys.modules
    node = AgentNode(FakeSession(), RUN, 1, {**reply, "brain": brain}, wait_world=False, trusted={"evil_leader:law"})
    assert node.brain.law is sys.modules["evil_leader"].law


def test_the_batch_engine_refuses_laws_of_ones_own(base, law_module):
    assert refusal(parse_scenario(base)) is None
    base["law"] = {"leader": "helpers_law:orbit_rate_leader"}
    assert "only the built-in 'cc' law" in refusal(parse_scenario(base))
    base["law"] = {"follower": "helpers_law:stateful_follower"}
    assert "only the built-in 'bearing' law" in refusal(parse_scenario(base))
    base["law"] = {"params": {"k": 1.0}}  # parameters alone: the built-in laws ignore them
    assert refusal(parse_scenario(base)) is None


def test_params_are_a_read_only_mapping(base):
    brain, _ = _brain(base, 2, {"params": {"a": 1}})
    assert isinstance(brain.params, MappingProxyType) and brain.params == {"a": 1.0}
