"""Tests for swarm.plots: PNGs of a synthetic run, and PlotError on bad input."""

from __future__ import annotations

import csv
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from cli_invoke import invoke
from matplotlib.colors import to_rgba
from synthetic_run import make_run

from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import EventKind, ExitCode, FollowState
from swarm.offline.csv_export import COLUMNS, csv_name, write_agent_csvs
from swarm.offline.sim import run_sim
from swarm.plots import (
    ANIMATION_FILE,
    PLOT_FILES,
    PlotError,
    check_formats,
    final_graph,
    load_run,
    render_animation,
    render_plots,
    switch_count,
)
from swarm.plots.animate import gif_frames
from swarm.plots.clipping import clip_text, control_range
from swarm.plots.context import make_context
from swarm.plots.graph import panel_graph
from swarm.plots.palette import agent_looks, palette
from swarm.plots.placement import spread_1d, stack_offsets
from swarm.plots.render import RC, figure, save_figure
from swarm.plots.style import EVENT_COLOURS, FAULT_COLOUR
from swarm.plots.trajectories import panel_trajectories
from swarm.study.figures import plot_sweep, sweep_figure
from swarm.world.recording import write_run

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# The documented plot files (docs/reference/outputs.md#plots), in the order render_plots returns them.
EXPECTED_PNGS = [
    "trajectories.png",
    "distance.png",
    "control.png",
    "graph.png",
    "overview.png",
    "neighbours.png",
    "states.png",
]


def assert_pngs(run_dir: Path, paths: list[Path], expected: list[str] = EXPECTED_PNGS) -> None:
    """`paths` are the documented files, in order, and exactly the PNGs now in `run_dir`."""
    assert paths == [run_dir / name for name in expected]
    assert sorted(p.name for p in run_dir.glob("*.png")) == sorted(expected)
    for p in paths:
        name = p.name
        data = p.read_bytes()
        assert len(data) > 1000, name
        assert data[:8] == PNG_MAGIC, name


ALL_FORMATS = ("png", "pdf", "svg")
RENDERED_FORMATS = ("png", "svg")  # the module's render (`rendered`); PDF: test_render_writes_every_format
LONG_TICKS, FEW_POINTS = 9001, 500  # more rows than points per line: decimated


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> dict:
    """One synthetic run's figures rendered once, as PNG and SVG, with fewer points per line
    than it has rows (render_plots(max_points=FEW_POINTS): the stride and the min/max envelope),
    leader 1 and followers 2 -> 1, 3 -> 2, 4 -> 3, 5 -> 4, 6 -> 5 of which follower 4 drops, so
    that 5 and 6 have no leader path: its dir, the paths returned, and matplotlib's open figures
    before and after (the tests below read it). PDF is test_render_writes_every_format's: every
    figure as PDF too cost 5-7 s of CPU (fontTools subsetting the fonts of each file), for the
    same writer (save_figure) that writes every figure in every format."""
    run_dir = make_run(tmp_path_factory.mktemp("rendered") / "run", ticks=LONG_TICKS, n_followers=5, drop=(2, 4000))
    pngs_before = list(run_dir.glob("*.png"))
    before = len(plt.get_fignums())
    paths = render_plots(run_dir, max_points=FEW_POINTS, formats=RENDERED_FORMATS)
    return {"run_dir": run_dir, "pngs_before": pngs_before, "paths": paths, "figs": (before, len(plt.get_fignums()))}


def pngs_of(rendered: dict) -> list[Path]:
    return [p for p in rendered["paths"] if p.suffix == ".png"]


@pytest.mark.slow  # a whole run in-process
def test_render_writes_every_png(rendered) -> None:
    run_dir = rendered["run_dir"]
    assert not rendered["pngs_before"]
    assert_pngs(run_dir, pngs_of(rendered))
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
def test_render_decimates_long_run(rendered) -> None:
    # more rows than max_points: exercises the stride and min/max envelope paths
    run = load_run(rendered["run_dir"])
    assert run.n_rows == LONG_TICKS + 1 > 4 * FEW_POINTS and len(run.ids) == 6
    assert_pngs(rendered["run_dir"], pngs_of(rendered))


@pytest.mark.slow  # many renders: the long tier
def test_render_does_not_leak_figures(rendered) -> None:
    before, after = rendered["figs"]  # (the render of the module's run)
    assert after == before


@pytest.mark.slow  # renders every figure: the long tier
def test_final_graph_flags_orphans(rendered) -> None:
    # leader 1, followers 2 -> 1, ..., 6 -> 5; follower 4 drops, so 5 and 6 have no leader path
    run = load_run(rendered["run_dir"])
    edges, dead, orphans = final_graph(run)
    assert edges == {2: 1, 3: 2, 4: 3, 5: 4, 6: 5}  # 4's edge is from its last alive row
    assert dead == {4}
    assert orphans == {5, 6}
    assert_pngs(rendered["run_dir"], pngs_of(rendered))  # drawn with them


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


# -- figures fit for a paper: formats, colours, the control range, labels, CSV, animation ------------

PDF_MAGIC = b"%PDF"


def assert_valid_figure(path: Path) -> None:
    """A whole file of its format: PNG magic, PDF header and trailer, SVG parsing as XML."""

    data = path.read_bytes()
    assert len(data) > 1000, path.name
    if path.suffix == ".png":
        assert data[:8] == PNG_MAGIC, path.name
    elif path.suffix == ".pdf":
        assert data.startswith(PDF_MAGIC) and b"%%EOF" in data[-64:], path.name
    else:
        assert ET.fromstring(data).tag == "{http://www.w3.org/2000/svg}svg", path.name


def regroup(run_dir: Path, n_leaders: int) -> Path:
    """Make every follower follow leader (k mod n_leaders): one tree per leader."""
    path = run_dir / "trajectory.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    ids, alive = arrays["ids"], arrays["alive"]
    for j in range(n_leaders, len(ids)):
        arrays["out"][:, j] = np.where(alive[:, j], ids[j % n_leaders], -1)
    np.savez(path, **arrays)
    summary = json.loads((run_dir / "summary.json").read_text())
    for j in range(n_leaders, len(ids)):
        summary["agents"][str(int(ids[j]))]["out_neighbour"] = int(ids[j % n_leaders])
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir


@pytest.mark.slow
def test_save_figure_writes_every_format(tmp_path: Path) -> None:
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1], label="L1")
    ax.set_title("tiny")
    paths = save_figure(fig, tmp_path / "tiny.png", ALL_FORMATS)
    assert [p.name for p in paths] == ["tiny.png", "tiny.pdf", "tiny.svg"]
    for p in paths:
        assert_valid_figure(p)
    assert not list(tmp_path.glob(".*.tmp"))  # written to a temporary name, then renamed
    assert not plt.fignum_exists(fig.number)


def test_unknown_format_is_refused() -> None:
    assert check_formats(["PDF", "png", "pdf"]) == ("pdf", "png")
    with pytest.raises(ValueError, match="'jpg'.*png, pdf, svg"):
        check_formats(["png", "jpg"])
    with pytest.raises(ValueError, match="no format"):
        check_formats([])


def test_every_agent_has_its_own_colour_and_leaders_are_marked(tmp_path: Path) -> None:
    for n in (6, 9, 18, 30, 54):
        cols = [tuple(c) for c in palette(n)]
        assert len(set(cols)) == n, n
        assert not [c for c in cols if abs(c[0] - c[1]) < 0.02 and abs(c[1] - c[2]) < 0.02]  # no grey: "dead"
    assert len({tuple(c) for c in palette(80)}) == 54  # cycled past the 54 colours
    run = load_run(regroup(make_run(tmp_path / "run", ticks=20, n_leaders=3, n_followers=27, drop=None), 3))
    looks = agent_looks(run)
    assert len({tuple(c) for c in looks.colours}) == 30
    assert looks.labels[:4] == ["L1", "L2", "L3", "4"]
    assert looks.width(0) > looks.width(3)
    assert [tr.root for tr in looks.trees] == [1, 2, 3]
    assert sorted(j for tr in looks.trees for j in tr.columns) == list(range(30))


def test_control_range_clips_the_leaders_start_on_case2(tmp_path: Path) -> None:
    """Case 2's leaders start at their 10 rad/s limit; the followers turn at about 1 rad/s.
    The y-range comes from the followers and leaves the spike out, marked as clipped."""

    scenario = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "case2.toml")
    write_run(run_sim(scenario, duration=3.0), tmp_path)
    run = load_run(tmp_path)
    rng = control_range(run)
    u = np.where(run.alive, run.u, np.nan)
    assert np.nanmax(u) >= 9.9  # the spike is there...
    assert rng.hi < 5.0  # ...and out of the range
    followers = u[:, run.followers()]
    assert rng.lo <= np.nanmin(followers) and np.nanmax(followers) <= rng.hi  # every follower sample in view
    assert rng.lo <= 0.0 <= rng.hi
    spike = rng.clipped[0]
    assert run.is_leader(spike.column) and spike.value >= 9.9 and spike.t == 0.0
    assert {c.column for c in rng.clipped} <= set(run.leaders())
    assert clip_text(rng.clipped, agent_looks(run)).startswith("clipped: 10 rad/s at t=0 (L6)")


def test_labels_and_markers_are_kept_apart() -> None:
    want = np.array([0.50, 0.50, 0.51, 0.10, 0.98, 0.99])
    got = spread_1d(want, 0.05, lo=0.0, hi=1.0)
    order = np.argsort(want, kind="stable")
    assert np.all(np.diff(got[order]) >= 0.05 - 1e-12)  # apart, order kept
    assert got.min() >= 0.0 and got.max() <= 1.0 + 1e-12
    assert abs(got[3] - 0.10) < 1e-12  # a label with room stays where it is
    off = stack_offsets(np.zeros(8), np.zeros(8), sep=4.0, step=7.0, levels=6)
    pos = off + 0.0
    assert len({(round(a, 6), round(b, 6)) for a, b in pos}) == 8  # no two markers on the same spot
    assert off[:, 1].max() == 5 * 7.0 and off[:, 0].max() == 4.0  # a second column after six


def test_export_csv_matches_the_trajectory(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=40, drop=(1, 20))
    paths = write_agent_csvs(run_dir)
    run = load_run(run_dir)
    assert [p.name for p in paths] == [csv_name(a) for a in run.ids]
    for j, path in enumerate(paths):
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
        assert tuple(rows[0]) == COLUMNS
        assert len(rows) - 1 == run.n_rows
        table = np.array([[float(v) for v in r] for r in rows[1:]])
        col = {name: table[:, k] for k, name in enumerate(COLUMNS)}
        np.testing.assert_allclose(col["t"], run.t, rtol=1e-9)
        np.testing.assert_allclose(col["x"], run.x[:, j], rtol=1e-8)
        np.testing.assert_allclose(col["u"], run.u[:, j], rtol=1e-8)  # NaN where u is NaN
        assert (col["out"] == run.out[:, j]).all() and (col["alive"] == run.alive[:, j]).all()
        r = np.hypot(run.x[:, j] - run.target[0], run.y[:, j] - run.target[1])
        np.testing.assert_allclose(col["radial_error"], r - col["expected_radius"], rtol=1e-7, atol=1e-7)


def test_cli_refuses_a_bad_format_and_exports_csv(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=20)
    res = invoke("plot", run_dir, "--format", "png,jpg")
    assert res.exit_code == ExitCode.USAGE and "--format" in res.stderr and "'jpg'" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.output
    assert not list(run_dir.glob("*.png"))  # refused before any work
    res = invoke("export", run_dir, "--csv", "--no-plots")
    assert res.exit_code == ExitCode.OK, res.output
    assert len(list((run_dir / "csv").glob("agent-*.csv"))) == 3


@pytest.mark.parametrize(
    "flag, written",
    [("--csv", "csv"), pytest.param("--ros2", "ros2", marks=pytest.mark.slow)],  # (a bag: 0.8 s)
)
def test_export_writes_only_what_was_asked_unless_the_results_are_missing(
    tmp_path: Path, monkeypatch, flag, written
) -> None:
    # issue 33: `swarm export --ros2` re-rendered every figure (62 s on a long run) to add a bag
    import swarm
    from swarm.api.runs import Results

    drawn: list[Path | None] = []  # the figures are drawn by Results.plot (tests above): here, whether they are
    monkeypatch.setattr(Results, "plot", lambda self, *a, **k: drawn.append(self.run_dir) or [])
    run_dir = tmp_path / "run"
    swarm.simulate(Path(__file__).resolve().parents[2] / "scenarios" / "case2.toml", duration=0.5, out=run_dir)
    data = {n: (run_dir / n).read_bytes() for n in ("trajectory.npz", "summary.json")}

    def export(*args: str) -> str:
        res = invoke("export", run_dir, *args)
        assert res.exit_code == ExitCode.OK, res.output
        return res.output

    out = export(flag)
    assert (run_dir / written).is_dir() and "nothing to recover" in out
    assert drawn == [] and {n: (run_dir / n).read_bytes() for n in data} == data
    export(flag, "--plots")  # asked for
    export()  # `swarm export DIR` alone draws them, as before
    assert drawn == [run_dir, run_dir]
    # a world killed before writing its results: they are rebuilt, and drawn (its world never drew them)
    drawn.clear()
    for name in data:
        (run_dir / name).unlink()
    out = export(flag)
    assert "recovered " in out and json.loads((run_dir / "summary.json").read_text())["complete"] is False
    assert drawn == [run_dir]
    (run_dir / "trajectory.npz").unlink()
    export(flag, "--no-plots")
    assert drawn == [run_dir] and (run_dir / "trajectory.npz").is_file()


@pytest.mark.slow  # renders every figure in two formats and the overview in a third: the long tier
def test_render_writes_every_format(rendered) -> None:
    """render_plots writes every figure in each format asked, in order (the module's render: PNG
    and SVG); PDF from the same writer, for the overview (four of the six panels: graph,
    trajectories, distance, control); save_figure's every format: test_save_figure_writes_every_format."""
    run_dir, paths = rendered["run_dir"], rendered["paths"]
    assert paths == [run_dir / Path(n).with_suffix("." + f).name for n in EXPECTED_PNGS for f in RENDERED_FORMATS]
    for p in paths:
        assert_valid_figure(p)
    ctx = make_context(load_run(run_dir), FEW_POINTS)
    with plt.rc_context(RC):  # render_plots' settings: TrueType fonts embedded
        (pdf,) = save_figure(figure("overview.png", ctx, ""), run_dir / "overview.png", ("pdf",))
    assert pdf == run_dir / "overview.pdf"
    assert_valid_figure(pdf)
    assert b"/FontFile2" in pdf.read_bytes()  # TrueType embedded (docs/reference/outputs.md#plots), not Type 3


@pytest.mark.slow  # draws two panels of a 30-agent run: the long tier
def test_a_large_swarm_is_drawn_by_tree_in_the_same_colours(tmp_path: Path) -> None:
    run_dir = regroup(make_run(tmp_path / "run", ticks=100, n_leaders=3, n_followers=27, drop=None), 3)
    ctx = make_context(load_run(run_dir))
    fig = figure("distance.png", ctx, "")
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert titles == ["tree of L1", "tree of L2", "tree of L3"]  # small multiples, a panel per tree
    plt.close(fig)
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 6), layout="constrained")
    panel_graph(a, ctx)
    panel_trajectories(b, ctx)
    nodes = [tuple(c.get_facecolor()[0]) for c in a.collections if len(c.get_offsets()) == 1]
    node_colours = {to_rgba(c) for c in nodes}
    line_colours = {to_rgba(line.get_color()) for line in b.lines if line.get_linestyle() == "-"}
    for colour in ctx.looks.colours:
        assert to_rgba(colour) in node_colours and to_rgba(colour) in line_colours
    plt.close(fig)


@pytest.mark.slow  # encodes a GIF: the long tier
def test_animation_writes_a_gif_of_several_frames(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "run", ticks=300, drop=(1, 150))  # 3 s
    seen = []
    path = render_animation(run_dir, max_frames=8, progress=lambda i, n: seen.append((i, n)))
    assert path == run_dir / ANIMATION_FILE
    assert path.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    assert gif_frames(path) == 8
    assert seen[-1] == (8, 8) and len(seen) == 8


def edit_run(run_dir: Path, **arrays_and_summary) -> Path:
    """Change trajectory.npz's arrays in place (by a function of the array) and/or replace
    summary.json's keys (`summary={...}`)."""
    summary_keys = arrays_and_summary.pop("summary", {})
    path = run_dir / "trajectory.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    for name, change in arrays_and_summary.items():
        change(arrays[name])
    np.savez(path, **arrays)
    summary = json.loads((run_dir / "summary.json").read_text())
    summary.update(summary_keys)
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir


def test_states_png_is_a_row_per_follower_in_the_colours_of_its_states(tmp_path: Path) -> None:
    """states.png: a row per follower, bars in each follow state's colour (the first follower
    acquires, keeps, coasts, searches, keeps; the one that drops is hatched after its drop),
    the legend naming the states the run has, not those it lacks."""
    from matplotlib.colors import to_hex

    from swarm.plots.states import STATE_COLOURS, panel_states

    run = load_run(make_run(tmp_path / "run"))
    assert run.follow is not None
    ctx = make_context(run)
    fig, ax = plt.subplots()
    try:
        panel_states(ax, ctx)
        colours = {to_hex(c.get_facecolor()[0]) for c in ax.collections}
        for state in (FollowState.ACQUIRE, FollowState.KEEP, FollowState.COAST, FollowState.SEARCH):
            assert to_hex(STATE_COLOURS[state]) in colours, state
        assert to_hex(STATE_COLOURS[FollowState.HOLD]) not in colours
        assert [t.get_text() for t in ax.get_yticklabels()] == [ctx.looks.labels[j] for j in run.followers()]
        words = [t.get_text() for t in fig.legends[0].get_texts()]
        assert words[0] == "acquire" and "keep" in words and words[-1] == "not alive"
        assert not any(w.startswith("hold") for w in words)
    finally:
        plt.close(fig)


@pytest.mark.slow
def test_a_run_without_follow_states_plots_everything_else(tmp_path: Path) -> None:
    """An older run directory (trajectory.npz without `follow`): every figure but states.png."""
    run_dir = make_run(tmp_path / "run", ticks=60, follow=False)
    assert load_run(run_dir).follow is None
    assert_pngs(run_dir, render_plots(run_dir), [n for n in EXPECTED_PNGS if n != "states.png"])


@pytest.mark.parametrize("switches, words", [(1, "1 switch)"), (2, "2 switches)")])
def test_titles_count_switches_in_the_singular_and_plural(tmp_path: Path, switches: int, words: str) -> None:
    def flip(out: np.ndarray) -> None:
        out[100:, 2] = 1  # follower 3: 2 -> 1 at tick 100 (one switch)
        if switches == 2:
            out[200:, 2] = 2  # and back at tick 200

    run = load_run(edit_run(make_run(tmp_path / "run", drop=None), out=flip))
    assert switch_count(run) == switches
    ctx = make_context(run)
    fig = figure("neighbours.png", ctx, "")
    fig_a = figure("graph.png", ctx, "")
    try:
        assert fig.axes[0].get_title().endswith(f"({words}"), fig.axes[0].get_title()
        title_a = fig_a.axes[0].get_title()
        assert title_a.endswith(words.rstrip(")")) and "switchs" not in title_a, title_a
    finally:
        plt.close(fig)
        plt.close(fig_a)


def spans_in(ax) -> list[tuple[str, float, float]]:
    """(label, x0, x1) of the shaded fault spans of an axes."""
    out = []
    for p in ax.patches:
        if p.get_label().startswith("_span "):
            xs = p.get_path().transformed(p.get_patch_transform()).vertices[:, 0]
            out.append((p.get_label()[len("_span ") :], float(xs.min()), float(xs.max())))
    return out


def test_a_lasting_fault_is_a_span_in_a_colour_no_agent_has(tmp_path: Path) -> None:
    """A fault with a duration (loss, noise, partition, delay) is shaded from its start to its
    end on both time panels (a kill stays a line); faults are drawn in a colour of their own;
    event labels are readable (7 pt or more)."""
    faults = [
        {"at": 1.0, "kind": "loss", "duration": 2.0, "probability": 0.3},
        {"at": 2.0, "kind": "partition", "agent": 2, "duration": 1.5},
        {"at": 4.5, "kind": "noise", "duration": 60.0, "std": 0.05},  # cut at the run's end, 6 s
        {"at": 2.5, "kind": "kill", "agent": 3},
    ]
    run = load_run(edit_run(make_run(tmp_path / "run"), summary={"faults": faults}))
    ctx = make_context(run)
    for name in ("distance.png", "control.png"):
        fig = figure(name, ctx, "")
        try:
            got = sorted(spans_in(fig.axes[0]))
            assert got == [("loss", 1.0, 3.0), ("noise", 4.5, 6.0), ("partition 2", 2.0, 3.5)], (name, got)
            span = next(p for p in fig.axes[0].patches if p.get_label().startswith("_span "))
            assert to_rgba(span.get_facecolor())[:3] == to_rgba(FAULT_COLOUR)[:3]
            sizes = [t.get_fontsize() for t in fig.axes[0].texts if t.get_rotation() == 90]
            assert sizes and min(sizes) >= 7.0
        finally:
            plt.close(fig)
    for n in (6, 9, 18, 30, 54):  # no agent's colour near the faults' (RGB distance)
        agents = np.array([to_rgba(c)[:3] for c in palette(n)])
        for colour in (EVENT_COLOURS[EventKind.FAULT], EVENT_COLOURS["kill"]):
            assert np.sqrt(((agents - np.array(to_rgba(colour)[:3])) ** 2).sum(axis=1)).min() > 0.3, (n, colour)


def test_a_leader_starting_at_the_target_is_drawn_above_it(tmp_path: Path) -> None:
    """Case 2's L1 starts 2 m from the target: its start marker goes above the target's star."""

    def at_target(x: np.ndarray) -> None:
        x[0, 0] = 2.0  # the target is at (2, -1)

    def also(y: np.ndarray) -> None:
        y[0, 0] = -1.0

    run = load_run(edit_run(make_run(tmp_path / "run"), x=at_target, y=also))
    fig, ax = plt.subplots()
    try:
        panel_trajectories(ax, make_context(run))
        target = [ln for ln in ax.lines if ln.get_marker() == "*" and ln.get_markersize() == 14]
        starts = [ln for ln in ax.lines if ln.get_marker() == "o" and ln.get_markerfacecolor() == "white"]
        assert len(target) == 1 and len(starts) == run.n_agents
        start_l1 = [ln for ln in starts if tuple(np.ravel(ln.get_xydata())) == (2.0, -1.0)]
        assert len(start_l1) == 1
        assert start_l1[0].get_zorder() > target[0].get_zorder()
        assert min(ln.get_zorder() for ln in starts) > target[0].get_zorder()
    finally:
        plt.close(fig)


@pytest.mark.slow
def test_the_clipped_note_leaves_the_title_clear(tmp_path: Path) -> None:
    """A leader's spike at t = 0.1 s (a realtime run's first ticks) is clipped and named in a
    note over the top edge: the panel's title is drawn above it, in the single figure and in
    the overview, where (c)'s title stays level with (d)'s."""

    def spike(u: np.ndarray) -> None:
        u[10:13, 0] = 10.0

    run = load_run(edit_run(make_run(tmp_path / "run"), u=spike))
    ctx = make_context(run)
    assert any(c.value > control_range(run).hi for c in control_range(run).clipped)
    for name, panel in (("control.png", 0), ("overview.png", 3)):
        fig = figure(name, ctx, " (synthetic, converged)")
        try:
            fig.canvas.draw()
            r = fig.canvas.get_renderer()  # type: ignore[attr-defined]
            ax = fig.axes[panel]
            notes = [t for t in ax.texts if t.get_text().startswith("clipped:")]
            assert len(notes) == 1
            note, title = notes[0].get_window_extent(r), ax.title.get_window_extent(r)
            assert title.y0 >= note.y1 - 0.5, (name, title, note)  # above the note: clear of it however long
            assert ax.title.get_text().startswith("(d) control inputs")
            if name == "overview.png":
                assert abs(fig.axes[2].title.get_window_extent(r).y0 - title.y0) < 1.0
        finally:
            plt.close(fig)


# -- swarm study scenario's sweep.png (swarm/study/figures.py) --------------------------------


def _sweep_rows(converged: bool) -> list[dict]:
    # as the study's rows.csv gives them back: strings
    return [
        {
            "param.k": str(k),
            "noise": str(n),
            "converged": str(converged),
            "settling_time": "3.5" if converged else "nan",
        }
        for k in (0.5, 1.0, 2.0)
        for n in (0.0, math.inf)
        for _ in range(2)
    ]


@pytest.mark.slow  # figures drawn and written: 0.6 s each
@pytest.mark.parametrize("converged", [False, True])
def test_sweep_axes_span_the_swept_values_even_when_no_run_converged(tmp_path, converged):
    # issue 33: with no converged run the settling panel had no data and its axis read -0.04..0.04, not k
    fig = sweep_figure(_sweep_rows(converged), ["param.k", "noise"], "a study")
    try:
        fig.canvas.draw()
        k_top, _, k_low, n_low = fig.axes
        for ax in (k_top, k_low):
            lo, hi = ax.get_xlim()
            assert lo < 0.5 and 2.0 < hi and hi - lo < 2.0, (lo, hi)
        assert k_low.get_xlabel() == "k"
        shown = [float(t.get_text().replace("\u2212", "-")) for t in k_low.get_xticklabels() if t.get_text()]
        lo, hi = k_low.get_xlim()
        inside = [v for v in shown if lo <= v <= hi]  # the tick labels read k: 0.5 .. 2.0
        assert inside[0] <= 0.5 and inside[-1] >= 2.0
        # a value that cannot be placed (inf): the values as categories
        assert [t.get_text() for t in n_low.get_xticklabels()] == ["0", "inf"]
        assert n_low.get_xlim()[0] < 0.0 < 1.0 < n_low.get_xlim()[1]
        texts = [t.get_text() for t in k_low.texts]
        if converged:
            assert texts == [] and k_low.get_ylim()[0] < 3.5 < k_low.get_ylim()[1]
        else:
            assert texts == ["no converged run"] and k_low.get_ylim() == (0.0, 1.0)
            assert not any(t.get_visible() and t.get_text() for t in k_low.get_yticklabels())
    finally:
        plt.close(fig)
    assert plot_sweep(_sweep_rows(converged), ["param.k"], tmp_path / "sweep.png", "t").stat().st_size > 1000
