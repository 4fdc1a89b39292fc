"""Follower laws (swarm.agents.laws), the follower side of AgentBrain, and the follower
equilibrium R_i = (v_i / v_j) R_j through the engine."""

from __future__ import annotations

import math
from pathlib import Path

import helpers_law
import numpy as np
import pytest

from swarm.agents.brain import AgentBrain, saturate
from swarm.agents.laws import bearing_law, make_follower_law
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.laws import LawError, resolve_law
from swarm.contracts.scenario import parse_scenario
from swarm.offline.sim import run_sim
from swarm.world.sensing import Contact, SensorFrame

TESTS = Path(__file__).resolve().parents[1] / "support"


@pytest.fixture
def law_module(monkeypatch):
    """tests/support/helpers_law.py, importable as `helpers_law` (its laws resolve by name)."""
    monkeypatch.syspath_prepend(str(TESTS))
    return helpers_law


# -- laws --------------------------------------------------------------------------------


@pytest.mark.parametrize("g_i, g_j, lam", [(0.0, 0.5, 1.0), (0.3, -2.0, 2.5), (-1.0, 1.2, -0.4)])
def test_bearing_law_formula(g_i, g_j, lam):
    c1, c2 = 0.7, 0.3
    expected = c1 * (g_j - g_i) + c2 * math.sin(lam - g_i)  # differences already in (-pi, pi)
    assert bearing_law(g_i, g_j, lam, c1, c2) == pytest.approx(expected, abs=1e-15)


def test_bearing_law_wraps_heading_difference():
    # g_j - g_i = 3 pi / 2 must act as -pi / 2 (turn the short way)
    u = bearing_law(-0.75 * math.pi, 0.75 * math.pi, 0.0, 1.0, 0.0)
    assert u == pytest.approx(-0.5 * math.pi)
    u = bearing_law(3.0, -3.0, 0.0, 2.0, 0.0)
    assert u == pytest.approx(2.0 * (2 * math.pi - 6.0))


def test_bearing_law_zero_on_aligned_pursuit():
    # same heading, target straight ahead: no turn
    assert bearing_law(0.4, 0.4, 0.4, 1.0, 0.5) == 0.0
    # same heading, out-neighbour to the left: turn left (positive)
    assert bearing_law(0.0, 0.0, 0.5, 1.0, 0.5) > 0


def test_registry_and_lookup():
    assert resolve_law("bearing") is bearing_law
    assert resolve_law("bearing") is bearing_law
    assert resolve_law("swarm.agents.laws:bearing_law") is bearing_law


def test_module_function_lookup(law_module):
    assert resolve_law("helpers_law:constant_law") is law_module.constant_law
    u = make_follower_law("helpers_law:gains_law", 2.0, 3.0)
    assert u(0.001, 0.002, 0.003) == pytest.approx(2003.0 + 0.001 * (0.001 + 0.02 + 0.3))


def test_make_follower_law_binds_gains():
    u = make_follower_law("bearing", 0.8, 0.2)
    assert u(0.1, 0.9, 1.4) == bearing_law(0.1, 0.9, 1.4, 0.8, 0.2)
    assert isinstance(u(0.1, 0.9, 1.4), float)


@pytest.mark.parametrize(
    "name, fragments",
    [
        ("bogus", ["unknown follower law 'bogus'", "bearing", "module:function"]),
        ("no_such_module_xyz:law", ["cannot import module 'no_such_module_xyz'"]),
        ("helpers_law:missing", ["module 'helpers_law' has no function 'missing'"]),
        ("helpers_law:NOT_A_FUNCTION", ["has no function 'NOT_A_FUNCTION'"]),
    ],
)
def test_unknown_law_raises_law_error(law_module, name, fragments):
    with pytest.raises(LawError) as exc:
        resolve_law(name)
    for frag in fragments:
        assert frag in str(exc.value)
    assert isinstance(exc.value, ValueError)


@pytest.mark.parametrize("c1, c2", [(math.nan, 1.0), (1.0, math.inf)])
def test_non_finite_gains_rejected(c1, c2):
    with pytest.raises(LawError, match="gains must be finite"):
        make_follower_law("bearing", c1, c2)


# -- AgentBrain, follower side ------------------------------------------------------------


def _brain(base, **agent_changes):
    for k, v in agent_changes.items():
        base["agents"][1][k] = v
    s = parse_scenario(base)
    return AgentBrain(BrainConf.from_scenario(s, 2), max_hops=10_000), s


def _frame(tick, heading, *contacts):
    return SensorFrame(tick, tick * 0.05, 2, heading, tuple(contacts))


def test_follower_decision_uses_law_on_pinned(base):
    brain, s = _brain(base)
    f = _frame(0, 0.2, Contact(1, 1.1, 0.9, 8.0), Contact(3, -0.5, 2.0, 1.0))
    d = brain.decide(f)
    assert d.out == 1 and d.phase == "track" and not d.fallback and d.tick == 0
    assert d.u == bearing_law(0.2, 0.9, 1.1, s.gains.c1, s.gains.c2)


def test_follower_falls_back_and_reports_it(base):
    brain, s = _brain(base)
    d = brain.decide(_frame(3, 0.0, Contact(3, 0.5, 1.0, 1.0)))
    assert d.out == 3 and d.fallback
    assert d.u == bearing_law(0.0, 1.0, 0.5, s.gains.c1, s.gains.c2)


def test_follower_lost_loiters_at_c2_in_its_last_direction(base):
    base["sensing"] = {"selection": "nearest"}  # sticky searches instead: tests/pure/test_search.py
    brain, s = _brain(base)
    d0 = brain.decide(_frame(0, 0.0, Contact(1, 1.0, 1.0, 3.0)))
    d1 = brain.decide(_frame(1, 0.0))
    assert d1.phase == "lost" and d1.out is None
    assert d0.u != 0.0 and d1.u == math.copysign(s.gains.c2, d0.u)
    d2 = brain.decide(_frame(2, 0.0))
    assert d2.u == d1.u  # a steady loiter circle of radius v / C2, not a spin


def test_follower_saturates_at_max_turn_rate(base):
    brain, _ = _brain(base, max_turn_rate=0.1)
    d = brain.decide(_frame(0, 0.0, Contact(1, 1.5, 2.5, 3.0)))
    assert d.u == 0.1
    d = brain.decide(_frame(1, 0.0, Contact(1, -1.5, -2.5, 3.0)))
    assert d.u == -0.1
    assert saturate(5.0, None) == 5.0


def test_follower_non_finite_law_output_holds_last(base, law_module):
    base["gains"]["law"] = "helpers_law:nan_law"
    brain, _ = _brain(base)
    brain.last_u = 0.25
    d = brain.decide(_frame(0, 0.0, Contact(1, 1.0, 1.0, 3.0)))
    assert d.u == 0.25


def test_leader_frame_without_target_is_an_error(base):
    s = parse_scenario(base)
    brain = AgentBrain(BrainConf.from_scenario(s, 1), max_hops=10_000)
    with pytest.raises(ValueError, match="no target"):
        brain.decide(SensorFrame(0, 0.0, 1, 0.0, ()))


# -- custom law through the engine ---------------------------------------------------------


def test_custom_law_is_used_by_run_sim(base, law_module):
    base["gains"]["law"] = "helpers_law:constant_law"
    s = parse_scenario(base)
    a = run_sim(s, duration=2.0).recorder.arrays()
    followers = a["role"] == "follower"
    assert followers.sum() == 2
    u = a["u"][:-1]
    assert np.all(u[:, followers] == law_module.CONSTANT_U)
    # the leader still flies its own plan (base leader starts on its orbit: u = v / R)
    assert np.allclose(u[:, ~followers], 0.5)


def test_custom_law_saturated_by_max_turn_rate_in_run_sim(base, law_module):
    base["gains"]["law"] = "helpers_law:fast_law"
    base["agents"][1]["max_turn_rate"] = 0.7
    s = parse_scenario(base)
    a = run_sim(s, duration=1.0).recorder.arrays()
    assert np.all(a["u"][:-1, 1] == 0.7)
    assert np.all(a["u"][:-1, 2] == 100.0)  # no limit on agent 3


# -- equilibrium R_i = (v_i / v_j) R_j ------------------------------------------------------

V_J, R_J = 2.0, 4.0
OMEGA = V_J / R_J  # 0.5 rad/s


def _pair(ratio, start, direction="ccw", dt=0.02, duration=150 / OMEGA):
    sign = 1 if direction == "ccw" else -1
    fx, fy, fh = start
    return parse_scenario(
        {
            "run": {"dt": dt, "duration": duration},
            "gains": {"c1": OMEGA, "c2": OMEGA / 2},
            "sensing": {"selection": "fixed"},
            "agents": [
                # leader already on its orbit, tangent heading
                {
                    "id": 1,
                    "role": "leader",
                    "x": R_J,
                    "y": 0.0,
                    "heading": sign * math.pi / 2,
                    "speed": V_J,
                    "orbit_radius": R_J,
                    "direction": direction,
                },
                {"id": 2, "role": "follower", "x": fx, "y": fy, "heading": fh, "speed": ratio * V_J, "follow": 1},
            ],
        },
        "pair",
    )


def _final_radius_and_rate(result, col, window):
    a = result.recorder.arrays()
    t, x, y = a["t"], a["x"][:, col], a["y"][:, col]
    k0 = int(np.searchsorted(t, t[-1] - window))
    theta = np.unwrap(np.arctan2(y[k0:], x[k0:]))
    return math.hypot(x[-1], y[-1]), (theta[-1] - theta[0]) / (t[-1] - t[k0])


@pytest.mark.slow  # a whole run in-process: the long tier
@pytest.mark.parametrize("ratio", [1.5, 0.6], ids=["faster", "slower"])
@pytest.mark.parametrize("start", [(0.0, -3.0, 0.0), (-5.0, 5.0, 2.0)], ids=["start-a", "start-b"])
def test_follower_settles_at_speed_ratio_radius(ratio, start):
    res = run_sim(_pair(ratio, start))
    expected = ratio * R_J
    r_lead, w_lead = _final_radius_and_rate(res, 0, 10 / OMEGA)
    assert abs(r_lead - R_J) < 1e-9 and abs(w_lead - OMEGA) < 1e-9  # leader stayed on orbit
    r, w = _final_radius_and_rate(res, 1, 10 / OMEGA)
    assert abs(r - expected) / expected < 1e-3
    assert abs(w - OMEGA) < 1e-3
    summary = res.summary()
    f = summary["agents"]["2"]
    assert f["root"] == 1 and f["hops"] == 1 and f["out_neighbour"] == 1
    assert f["expected_radius"] == pytest.approx(expected, rel=1e-12)
    assert f["relative_error"] < 1e-3
    assert summary["converged"]


@pytest.mark.slow
def test_follower_of_clockwise_leader_turns_clockwise():
    res = run_sim(_pair(1.5, (0.0, -3.0, 0.0), direction="cw", dt=0.05))
    r, w = _final_radius_and_rate(res, 1, 10 / OMEGA)
    assert abs(r - 1.5 * R_J) / (1.5 * R_J) < 1e-3
    assert abs(w + OMEGA) < 1e-3
