"""The second law from the literature (agents/spl_circle.py: Sepulchre, Paley & Leonard
2007, circular control about the target with splay-state phase coupling) and its
scenario: the documented equilibrium (radius R, neighbours 2 pi / N apart, turning at
omega0) is an equilibrium of the law, and `swarm sim` reaches it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarm.agents.spl_circle import spl_circle
from swarm.contracts.frames import Contact
from swarm.contracts.observation import Observation
from swarm.contracts.scenario import load_scenario
from swarm.offline.batch import refusal
from swarm.offline.sim import run_sim

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "spl-splay.toml"
V, R, N = 2.0, 10.0, 5
PARAMS = {"kappa": 0.1, "k_phase": 0.1}


def _obs(k: int, angles, headings, direction=1, params=PARAMS) -> Observation:
    """Agent k's observation of N agents at `angles` about the target (origin), `headings`."""
    x, y = R * math.cos(angles[k]), R * math.sin(angles[k])
    contacts = tuple(Contact(j, 0.0, headings[j], 1.0) for j in range(len(angles)) if j != k)
    return Observation(
        k,
        "leader",
        0,
        0.0,
        0.05,
        V,
        headings[k],
        None,
        contacts,
        None,
        (-x, -y),
        R,
        direction,
        1.0,
        0.5,
        params,
        {},
        0.0,
    )


@pytest.mark.parametrize("direction", [1, -1], ids=["ccw", "cw"])
def test_the_splay_circle_is_an_equilibrium(direction):
    angles = [0.3 + 2 * math.pi * k / N for k in range(N)]
    headings = [a + direction * math.pi / 2 for a in angles]  # tangent, in the orbit's direction
    for k in range(N):
        assert spl_circle(_obs(k, angles, headings, direction)) == pytest.approx(direction * V / R, abs=1e-12)


def test_off_the_equilibrium_it_steers():
    angles = [2 * math.pi * k / N for k in range(N)]
    headings = [a + math.pi / 2 for a in angles]
    bunched = [0.0, 0.1, 0.2, 0.3, 0.4]  # on the circle but not spread: the phase term acts
    u = [spl_circle(_obs(k, bunched, [a + math.pi / 2 for a in bunched])) for k in range(N)]
    assert max(abs(x - V / R) for x in u) > 1e-3
    outward = list(headings)
    outward[0] = angles[0]  # agent 0 heads straight out: the radial term turns it (ccw: left)
    assert spl_circle(_obs(0, angles, outward)) > V / R


def test_it_is_a_leader_law():
    obs = _obs(0, [0.0, 1.0], [0.0, 1.0])._replace(target=None, role="follower")
    with pytest.raises(ValueError, match=r"\[law\] leader"):
        spl_circle(obs)


@pytest.mark.slow  # a whole run in-process: the long tier
def test_swarm_sim_reaches_the_documented_equilibrium():
    s = load_scenario(SCENARIO)
    assert s.law.leader == "swarm.agents.spl_circle:spl_circle" and all(a.role == "leader" for a in s.agents)
    assert "leader law" in refusal(s)  # a law of one's own: per-agent engine only
    res = run_sim(s)
    a = res.recorder.arrays()
    t, x, y = a["t"], a["x"], a["y"]
    r = np.hypot(x[-1], y[-1])
    ang = np.sort(np.mod(np.arctan2(y[-1], x[-1]), 2 * math.pi))
    gaps = np.diff(np.r_[ang, ang[0] + 2 * math.pi])
    k0 = int(np.searchsorted(t, t[-1] - 10 / (V / R)))  # the last 10 / omega0 s
    theta = np.unwrap(np.arctan2(y[k0:], x[k0:]), axis=0)
    rate = (theta[-1] - theta[0]) / (t[-1] - t[k0])
    print(
        f"\n[spl] radius error {np.max(np.abs(r - R)):.2e} m, spacing error "
        f"{np.max(np.abs(gaps - 2 * math.pi / N)):.2e} rad, rate error {np.max(np.abs(rate - V / R)):.2e} rad/s"
    )
    assert np.max(np.abs(r - R)) < 1e-3 * R  # on the circle of radius R = v / |omega0|
    assert np.max(np.abs(gaps - 2 * math.pi / N)) < 1e-3  # the splay state: 2 pi / N apart
    assert np.max(np.abs(rate - V / R)) < 1e-3  # counter-clockwise at omega0
    assert res.summary()["converged"]
