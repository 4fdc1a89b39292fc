"""`render_plots`: read a run directory and write its figures (see `PLOT_FILES`) next to
the data, in PNG, PDF and/or SVG: one figure per panel plus the paper-like 2x2 overview.
Above `GROUP_ABOVE` agents distance and control become small multiples, a panel per tree
(groups.py); the overview keeps the paper's four panels."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from swarm.offline.results import PLOT_NAMES
from swarm.plots.clipping import control_range, title_pad_over_note, top_note
from swarm.plots.context import GROUP_ABOVE, Ctx, grouped, make_context
from swarm.plots.graph import panel_graph, panel_neighbours
from swarm.plots.groups import grouped_control, grouped_distance
from swarm.plots.states import has_states, panel_states
from swarm.plots.style import DPI, MAX_POINTS
from swarm.plots.timeseries import panel_control, panel_distance
from swarm.plots.trajectories import figure_size as trajectories_size
from swarm.plots.trajectories import panel_trajectories
from swarm.world.run_reader import RunData, load_run

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

#: Files written by `render_plots` (as PNG), in the order they are returned.
PLOT_FILES = PLOT_NAMES  # the list lives with the rest of a run directory's layout (swarm/offline/results.py)

#: The formats `render_plots` can write, by file suffix.
FORMATS = ("png", "pdf", "svg")

#: The panels of overview.png, row by row (the paper's (a)-(d)).
OVERVIEW = ("graph.png", "trajectories.png", "distance.png", "control.png")

#: PDF: TrueType fonts embedded (editable, accepted by publishers), not Type 3.
RC: dict[RcKeyType, Any] = {"pdf.fonttype": 42, "svg.fonttype": "path"}


def title_suffix(run: RunData) -> str:
    """ " (scenario, converged)" from the summary, "" when it says neither."""
    sc = run.summary.get("scenario")
    conv = run.summary.get("converged")
    parts = []
    if sc is not None:
        parts.append(str(sc))
    if isinstance(conv, bool):
        parts.append("converged" if conv else "not converged")
    return f" ({', '.join(parts)})" if parts else ""


def save_figure(fig: Figure, path: Path, formats: Iterable[str]) -> list[Path]:
    """Save `fig` as `path` with each format's suffix, each to a temporary name then
    renamed (a file is whole or absent); close the figure. Returns the files written."""
    written = []
    try:
        for fmt in formats:
            out = path.with_suffix("." + fmt)
            tmp = out.with_name(f".{out.name}.tmp")
            try:
                fig.savefig(tmp, dpi=DPI, format=fmt)
                tmp.replace(out)
            finally:
                tmp.unlink(missing_ok=True)
            written.append(out)
    finally:
        plt.close(fig)
    return written


def check_formats(formats: Iterable[str]) -> tuple[str, ...]:
    """The formats, lower-cased, in order, once each; ValueError naming an unknown one."""
    out: list[str] = []
    for f in formats:
        f = f.strip().lower().lstrip(".")
        if f not in FORMATS:
            raise ValueError(f"unknown format {f!r} (choose from {', '.join(FORMATS)})")
        if f not in out:
            out.append(f)
    if not out:
        raise ValueError(f"no format given (choose from {', '.join(FORMATS)})")
    return tuple(out)


def one_panel(size: tuple[float, float], draw: Callable[[Any], None], suffix: str) -> Figure:
    fig, ax = plt.subplots(figsize=size, layout="constrained")
    draw(ax)
    ax.title.set_text(ax.get_title() + suffix)  # (not set_title: it would reset a raised title's pad)
    return fig


def figure(name: str, ctx: Ctx, suffix: str) -> Figure:
    """The figure of the file `name` (one of PLOT_FILES)."""
    n_f = len(ctx.run.followers())
    big = ctx.run.n_agents > GROUP_ABOVE
    if name == "overview.png":
        fig, axs = plt.subplots(2, 2, figsize=(15 if big else 14, 12.5), layout="constrained")
        panel_graph(axs[0, 0], ctx)
        panel_trajectories(axs[0, 1], ctx, tree_legend=False)  # (a) names the colours
        panel_distance(axs[1, 0], ctx)
        panel_control(axs[1, 1], ctx)
        if top_note(control_range(ctx.run)):  # (d)'s title raised over its note: (c)'s level with it
            axs[1, 0].set_title(axs[1, 0].get_title(), pad=title_pad_over_note())
        fig.suptitle("Run overview" + suffix)
        return fig
    if name == "distance.png" and grouped(ctx):
        return grouped_distance(ctx, suffix)
    if name == "control.png" and grouped(ctx):
        return grouped_control(ctx, suffix)
    panels = {  # file -> (figure size, what draws the panel)
        "trajectories.png": (trajectories_size(ctx), lambda ax: panel_trajectories(ax, ctx)),
        "distance.png": ((9, 5.5), lambda ax: panel_distance(ax, ctx)),
        "control.png": ((9, 5.5), lambda ax: panel_control(ax, ctx)),
        "graph.png": ((7, 7), lambda ax: panel_graph(ax, ctx)),
        "neighbours.png": ((10, 1.9 + 0.35 * max(n_f, 1)), lambda ax: panel_neighbours(ax, ctx)),
        "states.png": ((10, 2.1 + 0.35 * max(n_f, 1)), lambda ax: panel_states(ax, ctx)),
    }
    size, draw = panels[name]
    return one_panel(size, draw, suffix)


def render_plots(run_dir: Path, max_points: int = MAX_POINTS, formats: Iterable[str] = ("png",)) -> list[Path]:
    """Write the run's figures into `run_dir` in each of `formats` (png, pdf, svg); return
    their paths: `PLOT_FILES` in order, each in the formats in the order given (but states.png
    for a run recorded without follow states: an older run directory)."""
    formats = check_formats(formats)
    run_dir = Path(run_dir)
    ctx = make_context(load_run(run_dir), max_points)
    suffix = title_suffix(ctx.run)
    paths: list[Path] = []
    with plt.rc_context(RC):
        for name in PLOT_FILES:
            if name == "states.png" and not has_states(ctx):
                continue
            paths += save_figure(figure(name, ctx, suffix), run_dir / name, formats)
    return paths
