"""Tests for swarm.agents.leader: Lemma 1 CC paths onto the orbit and orbit hold."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
from pathlib import Path

import cc_reference
import numpy as np
import pytest
from deadlines import DEADLINE

from swarm.agents.cc_plan import (
    CCPath,
    cc_coefficients,
    cc_radius_b,
    plan_cc,
)
from swarm.agents.leader import on_orbit_command
from swarm.contracts.orbits import wrap
from swarm.world.kinematics import step_one

ROOT = Path(__file__).resolve().parents[2]

# Sample sizes: the fast tier checks a sample (6 cases: a plan costs 10-30 ms of CPU here, the
# fast tier's tests stay under 0.2 s), the long tier the whole of it.
SAMPLE = pytest.mark.parametrize(
    "n", [pytest.param(6, id="sample"), pytest.param(None, id="all", marks=pytest.mark.slow)]
)


def arc_step(x, y, g, v, u, t):
    """One exact arc of the world's integrator, as Python floats (`step_one`: `step`'s bits,
    tests/pure/test_kinematics.py, without numpy's cost per scalar call)."""
    return step_one(float(x), float(y), float(g), float(v), float(u), float(t))


HALF_PI = 0.5 * math.pi


def _centres(path: CCPath, x, y, heading, radius, direction):
    """Arc centres o_A, o_B in B-at-origin coordinates (paper's Lemma 1 formulas)."""
    bx, by, beta = path.entry
    ax, ay = x - bx, y - by
    o_a = np.array([ax + path.r_a * math.sin(heading), ay - path.r_a * math.cos(heading)])
    o_b = np.array([-path.r_b * math.sin(beta), path.r_b * math.cos(beta)])
    return o_a, o_b


def _fly(path: CCPath, x, y, heading, v):
    x1, y1, g1 = arc_step(x, y, heading, v, path.u1, path.t1)
    return arc_step(x1, y1, g1, v, path.u2, path.t2)


def _check_path(path: CCPath, x, y, heading, v, radius, direction, max_turn_rate):
    # entry pose on the orbit, tangent in the orbit's direction
    bx, by, beta = path.entry
    assert math.hypot(bx, by) == pytest.approx(radius, rel=1e-12, abs=1e-12)
    phi = math.atan2(by, bx)
    assert abs(wrap(beta - (phi + direction * HALF_PI))) < 1e-9
    # the two arcs are tangent
    o_a, o_b = _centres(path, x, y, heading, radius, direction)
    gap = np.linalg.norm(o_a - o_b)
    scale = max(abs(path.r_a), abs(path.r_b), radius, math.hypot(x - bx, y - by))
    assert abs(gap - abs(path.r_a + path.r_b)) <= 1e-6 * scale
    # consistent rates, durations and length
    assert path.u1 == pytest.approx(-v / path.r_a, rel=1e-12)
    assert path.u2 == pytest.approx(v / path.r_b, rel=1e-12)
    assert path.t1 >= 0.0 and path.t2 >= 0.0
    assert path.length == pytest.approx(v * (path.t1 + path.t2), rel=1e-9, abs=1e-12)
    # after arc 1 the leader is on circle B, heading along it (the tangent point)
    x1, y1, g1 = arc_step(x, y, heading, v, path.u1, path.t1)
    on_b = np.array([x1 - bx, y1 - by]) - o_b
    assert abs(np.linalg.norm(on_b) - abs(path.r_b)) <= 1e-6 * scale
    expected_g1 = math.atan2(on_b[1], on_b[0]) + math.copysign(HALF_PI, path.r_b)
    assert abs(wrap(g1 - expected_g1)) < 1e-6
    # flying the arcs exactly lands on the entry pose
    xe, ye, ge = _fly(path, x, y, heading, v)
    assert path.length >= math.hypot(x - bx, y - by) * (1 - 1e-9)
    assert math.hypot(xe - bx, ye - by) < 1e-6
    assert abs(wrap(ge - beta)) < 1e-6
    # turn-rate limit
    if max_turn_rate is not None:
        assert abs(path.u1) <= max_turn_rate + 1e-12
        assert abs(path.u2) <= max_turn_rate + 1e-12
    else:
        assert abs(path.r_a) >= 0.1 * radius * (1 - 1e-12)
        assert abs(path.r_b) >= 0.1 * radius * (1 - 1e-12)


# --- Lemma 1 coefficients ----------------------------------------------------------------


def test_p3_paper_form_equals_derivation():
    rng = np.random.default_rng(0)
    n = 2000  # the draws up front (numpy's per-call cost was most of the test's time)
    axs, ays = rng.uniform(-50, 50, size=(2, n)).tolist()
    alphas, betas = rng.uniform(-math.pi, math.pi, size=(2, n)).tolist()
    for ax, ay, alpha, beta in zip(axs, ays, alphas, betas):
        if 1 - math.cos(alpha - beta) < 1e-3:
            continue
        p1, p2, p3 = cc_coefficients(ax, ay, alpha, beta)
        d = 1 - math.cos(alpha - beta)
        mine = (ax * ax + ay * ay) / (2 * d) + p1 * p2
        assert p3 == pytest.approx(mine, rel=1e-9, abs=1e-9 * (ax * ax + ay * ay) / d**2)


def test_lemma1_hyperbola_gives_tangent_circles():
    rng = np.random.default_rng(1)
    n = 2000  # the draws up front, the geometry on Python floats (numpy's per-call cost)
    axs, ays = rng.uniform(-20, 20, size=(2, n)).tolist()
    alphas, betas = rng.uniform(-math.pi, math.pi, size=(2, n)).tolist()
    r_as = (rng.choice([-1, 1], size=n) * rng.uniform(0.5, 30, size=n)).tolist()
    checked = 0
    for ax, ay, alpha, beta, r_a in zip(axs, ays, alphas, betas, r_as):
        if 1 - math.cos(alpha - beta) < 1e-3:
            continue
        p1, p2, p3 = cc_coefficients(ax, ay, alpha, beta)
        if abs(r_a - p1) < 1e-3:
            continue
        r_b = cc_radius_b(r_a, p1, p2, p3)
        o_a = (ax + r_a * math.sin(alpha), ay - r_a * math.cos(alpha))
        o_b = (-r_b * math.sin(beta), r_b * math.cos(beta))
        gap = math.hypot(o_a[0] - o_b[0], o_a[1] - o_b[1])
        assert gap == pytest.approx(abs(r_a + r_b), rel=1e-6, abs=1e-9)
        checked += 1
    assert checked > 1900


def test_cc_radius_b_straight_line_raises():
    p1, p2, p3 = cc_coefficients(3.0, -2.0, 0.3, 2.0)
    with pytest.raises(ValueError):
        cc_radius_b(p1, p1, p2, p3)


def test_cc_coefficients_parallel_headings_raise():
    with pytest.raises(ValueError):
        cc_coefficients(3.0, -2.0, 0.7, 0.7)
    with pytest.raises(ValueError):
        cc_coefficients(3.0, -2.0, 0.7, 0.7 + 2 * math.pi)


# --- the integrator and wrap as the leader uses them ------------------------------------------------------------------


def test_wrap_range():
    assert wrap(math.pi) == math.pi
    assert wrap(-math.pi) == math.pi
    assert wrap(3 * math.pi) == pytest.approx(math.pi)
    assert wrap(0.25) == 0.25
    assert wrap(-0.25 - 4 * math.pi) == pytest.approx(-0.25)


def test_arc_step_straight_and_circle():
    assert arc_step(1.0, 2.0, 0.0, 2.0, 0.0, 3.0) == pytest.approx((7.0, 2.0, 0.0))
    # a ccw circle of radius 5 around (0, 5): quarter turn from the origin
    v, r = 2.0, 5.0
    x, y, g = arc_step(0.0, 0.0, 0.0, v, v / r, (math.pi / 2) * r / v)
    assert (x, y, g) == pytest.approx((5.0, 5.0, math.pi / 2))
    # a full circle returns to the start
    x, y, g = arc_step(1.0, -1.0, 0.4, v, -v / r, 2 * math.pi * r / v)
    assert (x, y) == pytest.approx((1.0, -1.0), abs=1e-12)
    assert wrap(g - 0.4) == pytest.approx(0.0, abs=1e-12)


def test_arc_step_matches_fine_euler():
    x, y, g = 0.3, -0.2, 1.0
    v, u, t = 1.5, -0.7, 2.0
    n = 200_000
    dt = t / n
    ex, ey, eg = x, y, g
    for _ in range(n):  # midpoint rule
        gm = eg + 0.5 * u * dt
        ex += v * math.cos(gm) * dt
        ey += v * math.sin(gm) * dt
        eg += u * dt
    assert arc_step(x, y, g, v, u, t) == pytest.approx((ex, ey, wrap(eg)), abs=1e-9)


# --- plan_cc on random poses ------------------------------------------------------------


@pytest.mark.slow  # a whole run in-process: the long tier
@pytest.mark.parametrize("limited", [False, True])
def test_plan_cc_random_poses(limited):
    rng = np.random.default_rng(42 + limited)
    # 300 poses each way (a plan costs 10-30 ms of CPU: nearly all of this test's time); every
    # path of the port's comparison with the numpy planner below is checked the same way too,
    # 300 more, with and without limits
    for i in range(300):
        radius = rng.uniform(0.5, 80.0)
        v = rng.uniform(0.1, 15.0)
        direction = int(rng.choice([1, -1]))
        dist = radius * rng.uniform(0.1, 5.0)
        theta = rng.uniform(-math.pi, math.pi)
        heading = rng.uniform(-3 * math.pi, 3 * math.pi)
        x, y = dist * math.cos(theta), dist * math.sin(theta)
        max_rate = None
        if limited:
            # sometimes exactly the orbit's own turn rate (r_min == R)
            max_rate = v / radius if i % 5 == 0 else v / (radius * rng.uniform(0.05, 1.0))
        path = plan_cc(x, y, heading, v, radius, direction, max_rate)
        _check_path(path, x, y, heading, v, radius, direction, max_rate)


@SAMPLE
def test_plan_cc_near_orbit_poses(n):
    """Starts just off the orbit (beyond the on-orbit tolerance), nearly tangent either way."""
    rng = np.random.default_rng(11)
    for i in range(n or 400):
        radius, v = rng.uniform(0.5, 80.0), rng.uniform(0.1, 15.0)
        direction = int(rng.choice([1, -1]))
        dist = radius * (1 + rng.choice([1, -1]) * 10 ** rng.uniform(-8, -2))
        theta = rng.uniform(-math.pi, math.pi)
        heading = (
            theta + direction * HALF_PI + rng.choice([0.0, math.pi]) + rng.choice([1, -1]) * 10 ** rng.uniform(-12, -1)
        )
        max_rate = [None, v / radius, v / (radius * rng.uniform(0.05, 1.0))][i % 3]
        x, y = dist * math.cos(theta), dist * math.sin(theta)
        path = plan_cc(x, y, heading, v, radius, direction, max_rate)
        _check_path(path, x, y, heading, v, radius, direction, max_rate)


@SAMPLE
def test_plan_cc_is_reasonably_short(n):
    """The coarse default grid is within 1 % of a 10x finer entry grid."""
    rng = np.random.default_rng(7)
    for _ in range(max(1, n // 5) if n else 60):
        radius, v = rng.uniform(1, 20), rng.uniform(0.5, 5)
        direction = int(rng.choice([1, -1]))
        dist, theta, heading = radius * rng.uniform(0.1, 5), rng.uniform(-3, 3), rng.uniform(-3, 3)
        x, y = dist * math.cos(theta), dist * math.sin(theta)
        coarse = plan_cc(x, y, heading, v, radius, direction)
        fine = plan_cc(x, y, heading, v, radius, direction, n_entry=720)
        assert coarse.length <= 1.01 * fine.length + 1e-9


def test_plan_cc_one_arc_when_circle_touches_orbit():
    """From just outside the orbit, heading tangent: a single arc (r_B = s R) is optimal-ish."""
    radius, v, s = 10.0, 1.0, 1
    x, y, heading = 10.5, 0.0, math.pi / 2
    path = plan_cc(x, y, heading, v, radius, s)
    _check_path(path, x, y, heading, v, radius, s, None)
    # bounded by going straight-ish onto the orbit; certainly less than a quarter orbit
    assert path.length < 0.5 * math.pi * radius


# --- the pure-Python planner against the numpy one it replaced ------------------------------


def _port_cases(n, seed):
    """Seeded plan_cc arguments: random poses, radii, speeds, directions and turn-rate limits
    (none, exactly the orbit's own rate, or in between), a sixth of them just off the orbit."""
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        radius, v = float(rng.uniform(0.5, 80.0)), float(rng.uniform(0.1, 15.0))
        direction = int(rng.choice([1, -1]))
        theta = float(rng.uniform(-math.pi, math.pi))
        if i % 6 == 5:
            dist = radius * (1 + float(rng.choice([1, -1])) * 10 ** float(rng.uniform(-8, -2)))
            heading = theta + direction * HALF_PI + float(rng.uniform(-0.1, 0.1))
        else:
            dist = radius * float(rng.uniform(0.0, 5.0))
            heading = float(rng.uniform(-3 * math.pi, 3 * math.pi))
        max_rate = [None, v / radius, v / (radius * float(rng.uniform(0.05, 1.0)))][i % 3]
        cases.append((dist * math.cos(theta), dist * math.sin(theta), heading, v, radius, direction, max_rate))
    return cases


def _path_close(p: CCPath, q: CCPath, rel: float) -> bool:
    def close(a, b):
        return abs(a - b) <= rel * max(abs(a), abs(b)) + 1e-300

    return (
        all(
            close(a, b)
            for a, b in [
                (p.t1, q.t1),
                (p.t2, q.t2),
                (p.r_a, q.r_a),
                (p.r_b, q.r_b),
                (p.length, q.length),
                (p.entry[0], q.entry[0]),
                (p.entry[1], q.entry[1]),
            ]
        )
        and abs(wrap(p.entry[2] - q.entry[2])) <= rel * math.pi
    )


@SAMPLE
def test_plan_cc_port_matches_numpy_reference(n):
    """The pure-Python planner plans the numpy planner's paths (tests/support/cc_reference.py).

    numpy's AVX-512 log10 / power / arctan2 kernels round some last bits differently from
    libm (math), which can tip the refinement grid's middle |r_A| just below / above r_min
    and so pick r_min instead of the nudged r_min (1 + 1e-9): then the paths differ by
    ~1e-9 relative (a few percent of cases on such a machine), their lengths by less.
    Without those kernels the two are bit-for-bit equal (next test).
    """
    cases = _port_cases(n or 300, 2024)
    identical = within = 0
    for c in cases:
        want, got = cc_reference.plan_cc(*c), plan_cc(*c)
        _check_path(got, *c)  # a valid path, whatever the reference says
        if got == want:
            identical += 1
            continue
        assert got.length == pytest.approx(want.length, rel=1e-9, abs=1e-12), c
        if _path_close(got, want, 1e-9):
            within += 1
        else:  # a different boundary candidate: still a valid (checked above), equally short path
            assert _path_close(got, want, 1e-6), c
    print(
        f"plan_cc port vs numpy reference: {len(cases)} paths, {identical} identical, "
        f"{within} more within 1e-9, {len(cases) - identical - within} beyond (lengths within 1e-9)"
    )
    assert identical + within >= 0.9 * len(cases)


# numpy's own x86-64-v4 (AVX-512) kernels off: log10, power and arctan2 then come from libm
_NO_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR AVX512_SKX AVX512_CLX AVX512_CNL"
_BIT_EXACT = """
import json, math, sys
sys.path.insert(0, "tests/support")
import cc_reference
from swarm.agents.cc_plan import plan_cc
cases = json.loads(sys.argv[1])
print(sum(cc_reference.plan_cc(*c) != plan_cc(*c) for c in cases))
"""


@pytest.mark.skipif(
    platform.machine().lower() not in ("x86_64", "amd64"),
    reason="checked where numpy's non-AVX-512 float64 kernels are libm's",
)
@pytest.mark.slow  # a Python process of its own
def test_plan_cc_port_bit_exact_without_avx512_numpy():
    """Same algorithm, same float operations: with numpy's AVX-512 kernels disabled the port
    and the numpy reference give identical paths, to the last bit."""
    cases = _port_cases(120, 99)
    env = dict(os.environ, NPY_DISABLE_CPU_FEATURES=_NO_AVX512, PYTHONWARNINGS="ignore")
    p = subprocess.run(
        [sys.executable, "-c", _BIT_EXACT, json.dumps(cases)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env=env,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.split()[-1] == "0"


@pytest.mark.slow  # a Python process of its own
def test_importing_the_leader_does_not_load_numpy():
    """Leader processes stay as light as followers: swarm.agents.leader is numpy-free."""
    code = "import sys, swarm.agents.leader; sys.exit('numpy' in sys.modules)"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=DEADLINE, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:] or "swarm.agents.leader imported numpy"


# --- degenerate cases -------------------------------------------------------------------


@pytest.mark.parametrize("direction", [1, -1])
def test_already_on_orbit(direction):
    radius, v = 12.0, 2.0
    for theta in np.linspace(-math.pi, math.pi, 13):
        x, y = radius * math.cos(theta), radius * math.sin(theta)
        heading = theta + direction * HALF_PI
        path = plan_cc(x, y, heading, v, radius, direction, 0.5)
        assert path.t1 == 0.0 and path.t2 == 0.0 and path.length == 0.0
        assert path.u2 == pytest.approx(direction * v / radius)
        assert path.entry == pytest.approx((x, y, wrap(heading)), abs=1e-12)


@pytest.mark.slow  # 24 plans (about 0.3 s of CPU): the long tier
@pytest.mark.parametrize("direction", [1, -1])
def test_start_at_grid_entry_pose_and_grid_headings(direction):
    radius, v, n_entry = 8.0, 1.0, 72
    for k in (0, 5, 17, 40):
        phi = k * 2 * math.pi / n_entry
        beta = phi + direction * HALF_PI
        # exactly the entry pose of a grid candidate: on the orbit already
        path = plan_cc(radius * math.cos(phi), radius * math.sin(phi), beta, v, radius, direction)
        assert path.t1 == 0.0 and path.t2 == 0.0
        # a pose slightly off the orbit (beyond the on-orbit tolerance) with that heading,
        # so that alpha == beta exactly for this candidate
        for scale in (1.0 + 1e-6, 0.999, 1.3, 0.4):
            x, y = scale * radius * math.cos(phi), scale * radius * math.sin(phi)
            path = plan_cc(x, y, beta, v, radius, direction)
            _check_path(path, x, y, beta, v, radius, direction, None)
            if scale == 1.0 + 1e-6:
                assert path.length < 0.1 * radius
        # wrong direction on the orbit: must turn around
        x, y = radius * math.cos(phi), radius * math.sin(phi)
        path = plan_cc(x, y, beta + math.pi, v, radius, direction, 0.5)
        _check_path(path, x, y, beta + math.pi, v, radius, direction, 0.5)
        assert path.length > 0


@pytest.mark.parametrize("heading", [-math.pi, -2.0, -HALF_PI, 0.0, 0.3, HALF_PI, 2.5, math.pi])
@pytest.mark.parametrize("direction", [1, -1])
def test_start_at_target(heading, direction):
    radius, v = 10.0, 2.0
    for max_rate in (None, v / radius, 1.0):
        path = plan_cc(0.0, 0.0, heading, v, radius, direction, max_rate)
        _check_path(path, 0.0, 0.0, heading, v, radius, direction, max_rate)


@pytest.mark.slow  # 18 plans (about 0.4 s of CPU): the long tier
def test_far_away_and_pointing_away():
    radius, v = 5.0, 1.0
    for heading in np.linspace(-math.pi, math.pi, 9):
        for max_rate in (None, v / radius):
            path = plan_cc(100.0, -40.0, heading, v, radius, 1, max_rate)
            _check_path(path, 100.0, -40.0, heading, v, radius, 1, max_rate)


def test_plan_cc_input_errors():
    with pytest.raises(ValueError):  # orbit tighter than the turn-rate limit allows
        plan_cc(20.0, 0.0, 0.0, 1.0, 5.0, 1, max_turn_rate=0.1)
    with pytest.raises(ValueError):
        plan_cc(20.0, 0.0, 0.0, 0.0, 5.0, 1)
    with pytest.raises(ValueError):
        plan_cc(20.0, 0.0, 0.0, 1.0, -5.0, 1)
    with pytest.raises(ValueError):
        plan_cc(20.0, 0.0, 0.0, 1.0, 5.0, 0)


# --- orbit hold -------------------------------------------------------------------------


@pytest.mark.parametrize("direction", [1, -1])
def test_on_orbit_command_exact_on_orbit(direction):
    radius, v = 7.0, 1.5
    for theta in np.linspace(-math.pi, math.pi, 25):
        x, y = radius * math.cos(theta), radius * math.sin(theta)
        u = on_orbit_command(x, y, theta + direction * HALF_PI, v, radius, direction)
        assert u == direction * v / radius


@pytest.mark.parametrize("direction", [1, -1])
def test_on_orbit_stays_on_orbit(direction):
    radius, v, dt = 7.0, 1.5, 0.01
    x, y, g = radius, 0.0, direction * HALF_PI
    for _ in range(int(2 * 2 * math.pi * radius / v / dt)):
        u = on_orbit_command(x, y, g, v, radius, direction)
        x, y, g = arc_step(x, y, g, v, u, dt)
        assert abs(math.hypot(x, y) - radius) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize(
    "radius, v, direction, factor",
    [(10.0, 1.0, 1, 1.02), (10.0, 1.0, -1, 0.98), (2.0, 3.0, 1, 0.98), (50.0, 10.0, -1, 1.02)],
)
def test_on_orbit_command_converges_without_oscillation(radius, v, direction, factor):
    dt = 0.01
    period = 2 * math.pi * radius / v
    x, y, g = factor * radius, 0.0, direction * HALF_PI
    errors = []
    for _ in range(int(3 * period / dt)):
        u = on_orbit_command(x, y, g, v, radius, direction)
        x, y, g = arc_step(x, y, g, v, u, dt)
        errors.append((math.hypot(x, y) - radius) / radius)
    errors = np.array(errors)
    sign = math.copysign(1.0, factor - 1.0)
    # no overshoot to the other side (beyond rounding)
    assert np.all(sign * errors > -1e-9)
    # inside the 0.1 % band within one orbit period, and stays there
    k = int(period / dt)
    assert np.all(np.abs(errors[k:]) < 1e-3)
    assert abs(errors[-1]) < 1e-6


def test_on_orbit_command_saturates():
    u = on_orbit_command(30.0, 0.0, -HALF_PI, 1.0, 10.0, 1, max_turn_rate=0.2)
    assert u == pytest.approx(0.2) or u == pytest.approx(-0.2)
    u = on_orbit_command(30.0, 0.0, -HALF_PI, 1.0, 10.0, 1)
    assert abs(u) > 0.2
