"""Tests for swarm.plots: PNGs of a synthetic run, and PlotError on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from swarm.plots import PLOT_FILES, PlotError, final_graph, load_run, render_plots, switch_count

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# The documented plot files (README, "Outputs of a run"), in the order render_plots returns them.
EXPECTED_PNGS = ["trajectories.png", "distance.png", "control.png", "graph.png", "overview.png", "neighbours.png"]


def make_run(
    run_dir: Path,
    *,
    ticks: int = 600,
    dt: float = 0.01,
    n_leaders: int = 1,
    n_followers: int = 2,
    drop: tuple[int, int] | None = (1, 300),  # (follower index, tick) that drops
    events: bool = True,
) -> Path:
    """Write a synthetic run dir with the exact trajectory.npz / summary.json layout.

    Leaders orbit the target at r = 10; followers spiral in to r = 10 * speed ratio.
    Follower k follows agent k-1 (the first follows the first leader).
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    n = n_leaders + n_followers
    nt = ticks + 1
    t = np.arange(nt) * dt
    target = np.array([2.0, -1.0])
    ids = np.arange(1, n + 1, dtype=np.int64)
    role = np.array(["leader"] * n_leaders + ["follower"] * n_followers)
    speed = np.array([2.0] * n_leaders + [1.5 - 0.02 * k for k in range(n_followers)])
    orbit = np.array([10.0] * n_leaders + [np.nan] * n_followers)
    expected = np.where(np.isnan(orbit), 10.0 * speed / 2.0, orbit)
    # one extra sample so the heading comes from forward differences
    ts = np.arange(nt + 1) * dt
    xs = np.empty((nt + 1, n))
    ys = np.empty((nt + 1, n))
    for j in range(n):
        r0 = expected[j] if j < n_leaders else 18.0 + j
        r = expected[j] + (r0 - expected[j]) * np.exp(-ts / 1.5)
        phase = 2 * np.pi * j / n
        ang = phase + speed[j] / expected[j] * ts
        xs[:, j] = target[0] + r * np.cos(ang)
        ys[:, j] = target[1] + r * np.sin(ang)
    x, y = xs[:-1].copy(), ys[:-1].copy()
    heading = np.unwrap(np.arctan2(np.diff(ys, axis=0), np.diff(xs, axis=0)), axis=0)
    u = np.full((nt, n), np.nan)
    u[:-1] = np.diff(heading, axis=0) / dt
    out = np.full((nt, n), -1, dtype=np.int64)
    for j in range(n_leaders, n):
        out[:, j] = ids[j - 1] if j > n_leaders else ids[0]
    alive = np.ones((nt, n), dtype=bool)
    summary_events = []
    if drop is not None and drop[1] < nt:
        fk, tick = drop
        j = n_leaders + fk
        alive[tick:, j] = False
        out[tick:, j] = -1
        u[tick:, j] = np.nan
        x[tick:, j] = x[tick, j]
        y[tick:, j] = y[tick, j]
        summary_events.append(
            {"tick": tick, "time": tick * dt, "agent": int(ids[j]), "kind": "drop", "reason": "liveliness token lost"}
        )
    if events:
        summary_events.insert(0, {"tick": 0, "time": 0.0, "agent": 1, "kind": "join"})
        summary_events.append({"tick": 50, "time": 0.5, "agent": 3, "kind": "switch", "from": 1, "to": 2})
    np.savez(
        run_dir / "trajectory.npz",
        ids=ids,
        role=role,
        speed=speed,
        orbit_radius=orbit,
        target=target,
        dt=np.float64(dt),
        t=t,
        x=x,
        y=y,
        heading=heading,
        u=u,
        out=out,
        alive=alive,
    )
    summary = {
        "scenario": "synthetic",
        "converged": True,
        "ticks": ticks,
        "sim_time": ticks * dt,
        "agents": {
            str(int(ids[j])): {
                "role": str(role[j]),
                "out_neighbour": None if j < n_leaders else int(out[0, j]),
                "root": 1,
                "final_radius": float(expected[j]),
                "expected_radius": float(expected[j]),
                "alive": bool(alive[-1, j]),
            }
            for j in range(n)
        },
        "events": summary_events,
        "faults": [{"tick": 200, "time": 2.0, "kind": "kill", "agent": 3}],
    }
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir


def assert_pngs(run_dir: Path, paths: list[Path]) -> None:
    """`paths` are the documented files, in order, and exactly the PNGs now in `run_dir`."""
    assert paths == [run_dir / name for name in EXPECTED_PNGS]
    assert sorted(p.name for p in run_dir.glob("*.png")) == sorted(EXPECTED_PNGS)
    for p in paths:
        name = p.name
        data = p.read_bytes()
        assert len(data) > 1000, name
        assert data[:8] == PNG_MAGIC, name


def test_render_writes_every_png(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run")
    assert not list(run_dir.glob("*.png"))
    paths = render_plots(run_dir)
    assert_pngs(run_dir, paths)
    assert list(PLOT_FILES) == EXPECTED_PNGS  # the public list names what is written


def test_switches_are_counted_while_alive_only(tmp_path: Path) -> None:
    """The graph panel's count and the timeline come from switch_ticks: changes of `out`
    between two ticks at which the agent was alive (its first choice is not a switch)."""
    run_dir = make_run(tmp_path / "run", drop=None)
    with np.load(run_dir / "trajectory.npz") as z:
        arrays = {k: z[k] for k in z.files}
    out, alive = arrays["out"], arrays["alive"]
    before = switch_count(load_run(run_dir))
    out[100:200, 2] = 1  # follower 3: 2 -> 1 at tick 100, back at tick 200: two switches
    alive[:50, 1] = False  # follower 2 joins at tick 50: its first choice is no switch
    out[:50, 1] = -1
    alive[400:, 2] = False  # follower 3 drops at 400: no switch either
    np.savez(run_dir / "trajectory.npz", **arrays)
    assert switch_count(load_run(run_dir)) == before + 2


@pytest.mark.slow  # renders every figure: the long tier
def test_render_without_summary_and_single_row(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=0, drop=None, events=False)
    (run_dir / "summary.json").unlink()
    assert_pngs(run_dir, render_plots(run_dir))


@pytest.mark.slow  # long renders: the long tier
def test_render_decimates_long_run(tmp_path: Path) -> None:
    # more rows than MAX_POINTS: exercises the stride and min/max envelope paths
    run_dir = make_run(tmp_path / "run", ticks=9001, n_followers=5, drop=(2, 4000))
    assert_pngs(run_dir, render_plots(run_dir, max_points=500))


@pytest.mark.slow  # many renders: the long tier
def test_render_does_not_leak_figures(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    run_dir = make_run(tmp_path / "run", ticks=100)
    before = len(plt.get_fignums())
    render_plots(run_dir)
    assert len(plt.get_fignums()) == before


@pytest.mark.slow  # renders every figure: the long tier
def test_final_graph_flags_orphans(tmp_path: Path) -> None:
    # leader 1, followers 2 -> 1, 3 -> 2, 4 -> 3; follower 3 drops, so 4 has no leader path
    run_dir = make_run(tmp_path / "run", n_followers=3, drop=(1, 300))
    run = load_run(run_dir)
    edges, dead, orphans = final_graph(run)
    assert edges == {2: 1, 3: 2, 4: 3}  # 3's edge is from its last alive row
    assert dead == {3}
    assert orphans == {4}
    assert_pngs(run_dir, render_plots(run_dir))


def test_missing_trajectory_raises(tmp_path: Path) -> None:
    run_dir = tmp_path / "empty"
    run_dir.mkdir()
    with pytest.raises(PlotError, match="trajectory.npz"):
        render_plots(run_dir)


@pytest.mark.parametrize("key", ["x", "alive", "ids"])
def test_missing_key_raises(tmp_path: Path, key: str) -> None:
    run_dir = make_run(tmp_path / "run", ticks=20)
    path = run_dir / "trajectory.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != key}
    np.savez(path, **arrays)
    with pytest.raises(PlotError, match="trajectory.npz") as exc:
        render_plots(run_dir)
    assert key in str(exc.value)


def test_bad_shape_and_corrupt_file_raise(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=20)
    path = run_dir / "trajectory.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["u"] = arrays["u"][:-1]
    np.savez(path, **arrays)
    with pytest.raises(PlotError, match="trajectory.npz.*'u'"):
        render_plots(run_dir)
    path.write_bytes(b"not a zip")
    with pytest.raises(PlotError, match="trajectory.npz"):
        render_plots(run_dir)


def test_bad_summary_raises(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=20)
    (run_dir / "summary.json").write_text("{not json")
    with pytest.raises(PlotError, match="summary.json"):
        render_plots(run_dir)
