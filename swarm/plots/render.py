"""`render_plots`: read a run directory and write its PNGs (see `PLOT_FILES`) next to
the data, one figure per panel plus the paper-like 2x2 overview."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt

from swarm.plots.graph import panel_graph, panel_neighbours
from swarm.plots.style import DPI, MAX_POINTS, agent_colours, decimation_rows
from swarm.plots.timeseries import panel_control, panel_distance
from swarm.plots.trajectories import panel_trajectories
from swarm.results import PLOT_NAMES
from world.run_reader import RunData, load_run, run_events

#: Files written by `render_plots`, in the order they are returned.
PLOT_FILES = PLOT_NAMES  # the list lives with the rest of a run directory's layout (swarm/results.py)

#: The panels of overview.png, row by row (the paper's (a)-(d)).
OVERVIEW = ("graph.png", "trajectories.png", "distance.png", "control.png")


def title_suffix(run: RunData) -> str:
    """" (scenario, converged)" from the summary, "" when it says neither."""
    sc = run.summary.get("scenario")
    conv = run.summary.get("converged")
    parts = []
    if sc is not None:
        parts.append(str(sc))
    if isinstance(conv, bool):
        parts.append("converged" if conv else "not converged")
    return f" ({', '.join(parts)})" if parts else ""


def _save(fig: Any, path: Path) -> None:
    """Save to a temporary name, then rename: a PNG is whole or absent."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        fig.savefig(tmp, dpi=DPI, format="png")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)


def render_plots(run_dir: Path, max_points: int = MAX_POINTS) -> list[Path]:
    """Write the run's PNG plots into `run_dir`; return their paths (see `PLOT_FILES`)."""
    run_dir = Path(run_dir)
    run = load_run(run_dir)
    max_points = max(16, int(max_points))
    rows = decimation_rows(run, max_points)
    colours = agent_colours(run)
    events = run_events(run)
    suffix = title_suffix(run)
    n_f = len(run.followers())
    panels = {  # file -> (figure size, what draws the panel)
        "trajectories.png": ((7.5, 7), lambda ax: panel_trajectories(ax, run, rows, colours)),
        "distance.png": ((9, 5), lambda ax: panel_distance(ax, run, rows, colours, events)),
        "control.png": ((9, 5), lambda ax: panel_control(ax, run, colours, events, max_points)),
        "graph.png": ((7, 7), lambda ax: panel_graph(ax, run, colours)),
        "neighbours.png": ((10, 1.9 + 0.35 * max(n_f, 1)), lambda ax: panel_neighbours(ax, run, colours)),
    }
    paths = [run_dir / name for name in PLOT_FILES]
    for path in paths:
        if path.name == "overview.png":
            fig, axs = plt.subplots(2, 2, figsize=(14, 12), layout="constrained")
            for ax, (_, draw) in zip(axs.flat, (panels[k] for k in OVERVIEW)):
                draw(ax)
            fig.suptitle("Run overview" + suffix)
        else:
            size, draw = panels[path.name]
            fig, ax = plt.subplots(figsize=size, layout="constrained")
            draw(ax)
            ax.set_title(ax.get_title() + suffix)
        _save(fig, path)
    return paths
