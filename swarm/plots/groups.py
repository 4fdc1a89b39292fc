"""Small multiples for a large swarm: distance.png and control.png as one panel per tree
(each leader with the followers whose path ends at it; a tree of more than PER_PANEL
agents split over several panels; agents with no leader last), sharing the time axis,
the control panels sharing one y-range so that they compare."""

from __future__ import annotations

import math
from collections.abc import Callable

import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from swarm.plots.clipping import control_range
from swarm.plots.context import Ctx, panel_groups
from swarm.plots.style import DEAD_COLOUR, EXPECTED_COLOUR
from swarm.plots.timeseries import panel_control, panel_distance

PANEL_W, PANEL_H = 6.5, 2.9  # inches per small-multiple panel


def small_multiples(ctx: Ctx, draw: Callable[[Axes, str, list[int]], None], title: str) -> Figure:
    groups = panel_groups(ctx)
    ncol = 1 if len(groups) <= 3 else 2
    nrow = math.ceil(len(groups) / ncol)
    fig, axs = plt.subplots(
        nrow,
        ncol,
        figsize=(PANEL_W * ncol + 0.6, PANEL_H * nrow + 1.0),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    for ax, (name, cols) in zip(axs.flat, groups):
        draw(ax, name, cols)
    for ax in list(axs.flat)[len(groups) :]:
        ax.set_visible(False)
    for col in range(ncol):  # the time axis under the last panel of each column
        shown = [axs[r, col] for r in range(nrow) if axs[r, col].get_visible()]
        for ax in shown[:-1]:
            ax.set_xlabel("")
        if shown:
            shown[-1].xaxis.set_tick_params(labelbottom=True)
    fig.suptitle(title)
    return fig


def grouped_distance(ctx: Ctx, suffix: str) -> Figure:
    def draw(ax: Axes, name: str, cols: list[int]) -> None:
        panel_distance(ax, ctx, cols, title=name, legend=False)

    fig = small_multiples(ctx, draw, "(c) distance from target, by tree" + suffix)
    key = [
        Line2D([], [], color="0.3", lw=2.0 * ctx.looks.lw, label="leader (L)"),
        Line2D([], [], ls="--", color=EXPECTED_COLOUR, label="expected radius"),
        Line2D([], [], ls="", marker="|", ms=9, mew=1.6, color="0.3", label="out-neighbour switch"),
    ]
    if not ctx.run.alive[-1].all():
        key.append(Line2D([], [], ls=":", color=DEAD_COLOUR, label="dead / coasting"))
    fig.legend(handles=key, loc="outside lower center", ncol=len(key), fontsize=7)
    return fig


def grouped_control(ctx: Ctx, suffix: str) -> Figure:
    rng = control_range(ctx.run)

    def draw(ax: Axes, name: str, cols: list[int]) -> None:
        panel_control(ax, ctx, cols, title=name, rng=rng, legend=False)

    fig = small_multiples(ctx, draw, "(d) control inputs, by tree" + suffix)
    key = [Line2D([], [], color="0.3", lw=2.0 * ctx.looks.lw, label="leader (L)")]
    if rng.clipped:
        key.append(Line2D([], [], ls="", marker="^", ms=7, mfc="0.6", mec="k", label="clipped (beyond the axis)"))
    fig.legend(handles=key, loc="outside lower center", ncol=len(key), fontsize=7)
    return fig
