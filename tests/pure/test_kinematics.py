"""swarm.world.kinematics: exact arc integration of the unicycle, and angle wrapping."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarm.world.kinematics import step, step_one, wrap


def _rk4(x, y, g, v, u, t, n):
    """Reference: classical RK4 on x' = v cos g, y' = v sin g, g' = u with n substeps."""
    h = t / n

    def f(s):
        return np.array([v * math.cos(s[2]), v * math.sin(s[2]), u])

    s = np.array([x, y, g], dtype=float)
    for _ in range(n):
        k1 = f(s)
        k2 = f(s + 0.5 * h * k1)
        k3 = f(s + 0.5 * h * k2)
        k4 = f(s + h * k3)
        s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s


@pytest.mark.parametrize("v, dt, n, sign", [(1.3, 0.01, 1000, 1), (0.2, 0.05, 400, -1), (25.0, 0.01, 157, 1)])
def test_full_circle_closes(v, dt, n, sign):
    length = v * dt * n  # circumference covered in exactly n steps
    u = sign * 2 * math.pi * v / length
    x, y, g = 3.0, -1.0, 0.4
    for _ in range(n):
        x, y, g = step(x, y, g, v, u, dt)
    assert abs(x - 3.0) < 1e-9 and abs(y + 1.0) < 1e-9
    assert abs(wrap(g - 0.4)) < 1e-9


def test_half_circle_reaches_the_diameter():
    # u = v / R: after pi R / v seconds the agent is 2R away, heading reversed
    v, R, dt = 2.0, 5.0, 0.01
    n = 1000
    dt = math.pi * R / v / n
    x, y, g = 0.0, 0.0, 0.0
    for _ in range(n):
        x, y, g = step(x, y, g, v, v / R, dt)
    assert x == pytest.approx(0.0, abs=1e-9)
    assert y == pytest.approx(2 * R, abs=1e-9)
    assert abs(wrap(g - math.pi)) < 1e-9


def test_straight_line_when_u_is_zero():
    x, y, g = 1.0, 2.0, 0.7
    for _ in range(100):
        x, y, g = step(x, y, g, 3.0, 0.0, 0.1)
    assert x == pytest.approx(1.0 + 30.0 * math.cos(0.7), abs=1e-12)
    assert y == pytest.approx(2.0 + 30.0 * math.sin(0.7), abs=1e-12)
    assert g == 0.7


@pytest.mark.slow
@pytest.mark.parametrize("u, dt", [(0.8, 0.5), (-3.0, 0.2), (1e-7, 1.0), (12.0, 0.3)])
def test_matches_fine_rk4(u, dt):
    x0, y0, g0, v = 0.3, -0.2, 2.9, 1.7
    ref = _rk4(x0, y0, g0, v, u, dt, 20000)
    x, y, g = step(x0, y0, g0, v, u, dt)
    assert x == pytest.approx(ref[0], abs=1e-11)
    assert y == pytest.approx(ref[1], abs=1e-11)
    assert abs(wrap(g - ref[2])) < 1e-11


def test_heading_is_wrapped():
    _, _, g = step(0.0, 0.0, 3.1, 1.0, 1.0, 0.1)  # 3.2 rad -> 3.2 - 2 pi
    assert g == pytest.approx(3.2 - 2 * math.pi, abs=1e-12)
    _, _, g = step(0.0, 0.0, -3.1, 1.0, -1.0, 0.1)
    assert g == pytest.approx(2 * math.pi - 3.2, abs=1e-12)
    rng = np.random.default_rng(0)
    g0 = rng.uniform(-math.pi, math.pi, 1000)
    u = rng.uniform(-50, 50, 1000)
    _, _, g = step(np.zeros(1000), np.zeros(1000), g0, np.ones(1000), u, 0.3)
    assert np.all(g > -math.pi) and np.all(g <= math.pi)


def test_vectorised_equals_scalar():
    rng = np.random.default_rng(1)
    n = 50
    x, y = rng.normal(size=n), rng.normal(size=n)
    g = rng.uniform(-math.pi, math.pi, n)
    v = rng.uniform(0.1, 10, n)
    u = rng.uniform(-5, 5, n)
    u[:5] = 0.0
    vx, vy, vg = step(x, y, g, v, u, 0.05)
    assert vx.shape == (n,)
    for k in range(n):
        sx, sy, sg = step(x[k], y[k], g[k], v[k], u[k], 0.05)
        assert (sx, sy, sg) == (vx[k], vy[k], vg[k])


def test_speed_preserved_by_chord():
    # the chord of an arc with turn angle a has length v dt sin(a/2)/(a/2)
    v, u, dt = 2.0, 4.0, 0.5
    x, y, _ = step(0.0, 0.0, 0.0, v, u, dt)
    half = u * dt / 2
    assert math.hypot(x, y) == pytest.approx(v * dt * math.sin(half) / half, rel=1e-14)


def test_wrap_values():
    a = np.array([0.0, math.pi, 3 * math.pi / 2, -3 * math.pi / 2, 7.0, -7.0, 100.0])
    w = wrap(a)
    assert np.allclose(
        w,
        [0.0, math.pi, -math.pi / 2, math.pi / 2, 7.0 - 2 * math.pi, 2 * math.pi - 7.0, 100.0 - 32 * math.pi],
        atol=1e-12,
    )
    assert np.all(np.abs(np.sin(w) - np.sin(a)) < 1e-12)


def test_wrap_minus_pi_is_pi():
    assert wrap(-math.pi) == math.pi


@pytest.mark.slow
def test_step_one_is_step_to_the_bit():
    """The one-agent step on Python floats gives the array step's bits (WorldCore uses the
    first for small swarms and the second for large ones; the batch engine the second)."""
    rng = np.random.default_rng(12)
    n = 20000
    x, y = rng.uniform(-500, 500, n), rng.uniform(-500, 500, n)
    g = np.concatenate([rng.uniform(-math.pi, math.pi, n - 4), [math.pi, -math.pi + 1e-15, 3.0, -3.0]])
    v = rng.uniform(0.1, 60.0, n)
    u = np.concatenate([rng.uniform(-5, 5, n // 2), np.zeros(n // 4), rng.uniform(-1e-9, 1e-9, n - n // 2 - n // 4)])
    for dt in (0.01, 0.05):
        ax, ay, ag = step(x, y, g, v, u, dt)
        one = [step_one(*args, dt) for args in zip(x.tolist(), y.tolist(), g.tolist(), v.tolist(), u.tolist())]
        assert [p[0] for p in one] == ax.tolist()
        assert [p[1] for p in one] == ay.tolist()
        assert [p[2] for p in one] == ag.tolist()


def test_step_one_gives_nan_where_step_does():
    """Turn rates so large that the angles overflow: NaN where the array step gives NaN (numpy
    warns; math's functions would raise and end the world), the same numbers elsewhere."""
    import warnings

    def same(a, b):
        return all((math.isnan(p) and math.isnan(q)) or p == q for p, q in zip(a, b))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for g in (3.0, -math.pi, math.nan):
            for u, dt in [
                (1e308, 1.0),
                (-1e308, 2.0),
                (1.7e308, 1.0),
                (math.inf, 0.01),
                (math.nan, 0.01),
                (1e300, 1e8),
                (1e308, 0.01),
            ]:
                arr = [
                    float(v[0])
                    for v in step(np.array([1.0]), np.array([2.0]), np.array([g]), np.array([5.0]), np.array([u]), dt)
                ]
                assert same(arr, step_one(1.0, 2.0, g, 5.0, u, dt)), (g, u, dt)


def test_small_and_large_swarms_step_alike(monkeypatch):
    """WorldCore.step agent by agent equals the array step, with agents active, coasting and gone."""
    import swarm.world.core as core_mod
    from swarm.contracts.scenario import load_scenario

    scenario = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "case2.toml")
    scenario = scenario.model_copy(update={"run": scenario.run.model_copy(update={"on_dropout": "coast"})})
    runs = []
    for limit in (10**6, 0):
        monkeypatch.setattr(core_mod, "STEP_ONE_BY_ONE", limit)
        c = core_mod.WorldCore(scenario)
        for k in range(400):
            for aid in c.scenario.ids:
                c.set_command(aid, math.sin(0.01 * k + aid))
            if k == 100:
                c.drop(c.scenario.ids[1])  # coasts
            if k == 200:
                c.state[c.index[c.scenario.ids[2]]] = core_mod.GONE
            c.step()
        runs.append((c.x.tolist(), c.y.tolist(), c.heading.tolist()))
    assert runs[0] == runs[1]
