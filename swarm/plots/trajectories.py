"""Panel (b): x-y paths with start/final markers, the target and the expected orbits.

Up to `GROUP_ABOVE` agents every final position is labelled, labels placed clear of each
other and of the markers; in a larger swarm only the leaders are, and a legend grouped by
tree (a column per leader) names every colour. Leaders: thicker lines, a star at the end."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from swarm.plots.context import GROUP_ABOVE, Ctx
from swarm.plots.palette import FOLLOWER_MARKER, LEADER_MARKER, tree_legend_handles
from swarm.plots.placement import axes_size_pt, ha_va, place_point_labels
from swarm.plots.style import DEAD_COLOUR, EXPECTED_COLOUR, TARGET_COLOUR, key_legend, size_for, split_alive
from swarm.world.run_reader import expected_radii, first_alive, last_alive

TARGET_Z = 6.0  # the target's star: above every path and final marker
START_Z = 6.5  # the start markers: above the target's star, under the labels (7)


def final_position(ctx: Ctx, j: int) -> tuple[float, float] | None:
    """Last row's position, else the last alive one; None if never finite."""
    run = ctx.run
    fx, fy = run.x[-1, j], run.y[-1, j]
    last = last_alive(run.alive[:, j])
    if not (np.isfinite(fx) and np.isfinite(fy)) and last is not None:
        fx, fy = run.x[last, j], run.y[last, j]
    return (float(fx), float(fy)) if np.isfinite(fx) and np.isfinite(fy) else None


def figure_size(ctx: Ctx) -> tuple[float, float]:
    """trajectories.png's size (inches): its axes as wide as 7 in or as tall as 7.5 in, in
    the shape of the paths (equal aspect), plus room for the legends."""
    xs, ys = ctx.run.x[np.isfinite(ctx.run.x)], ctx.run.y[np.isfinite(ctx.run.y)]
    ratio = 1.0 if not xs.size else (np.ptp(ys) + 1e-9) / (np.ptp(xs) + 1e-9)
    ratio = min(max(ratio, 0.45), 1.6)
    w = min(7.0, 7.5 / ratio)
    extra = 0.0
    if ctx.run.n_agents > GROUP_ABOVE:
        _, ncol = tree_legend_handles(ctx.looks)
        extra = 1.05 * ncol + 0.4
    return w + 1.0 + extra, w * ratio + 1.9


def panel_trajectories(ax: Axes, ctx: Ctx, tree_legend: bool | None = None) -> None:
    run, looks, rows = ctx.run, ctx.looks, ctx.rows
    tx, ty = run.target
    for r in expected_radii(run):
        ax.add_patch(Circle((tx, ty), r, fill=False, ls="--", lw=0.9, ec=EXPECTED_COLOUR, zorder=1))
    finals: dict[int, tuple[float, float]] = {}
    starts = []
    for j in range(run.n_agents):
        col = run.alive[:, j]
        first = first_alive(col)
        live_x, dead_x = split_alive(run.x[:, j], col, first)
        live_y, dead_y = split_alive(run.y[:, j], col, first)
        ax.plot(
            live_x[rows],
            live_y[rows],
            color=looks.colours[j],
            lw=looks.width(j),
            alpha=0.9,
            zorder=2.5 if looks.leader[j] else 2,
        )
        if np.isfinite(dead_x[rows]).any():
            ax.plot(dead_x[rows], dead_y[rows], color=DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
        s = first if first is not None else 0
        if np.isfinite(run.x[s, j]) and np.isfinite(run.y[s, j]):
            starts.append((run.x[s, j], run.y[s, j]))
            ax.plot(  # above the target's star: a leader may start next to the target (case 2's L1)
                run.x[s, j], run.y[s, j], marker="o", ms=4, mfc="white", mec=looks.colours[j], mew=1.0, zorder=START_Z
            )
        end = final_position(ctx, j)
        if end is None:
            continue
        finals[j] = end
        alive_end = bool(col[-1])
        if alive_end:
            ax.plot(
                *end,
                marker=LEADER_MARKER if looks.leader[j] else FOLLOWER_MARKER,
                ms=13 if looks.leader[j] else 6,
                mfc=looks.colours[j],
                mec="k",
                mew=0.6,
                zorder=4.5,
            )
        else:
            ax.plot(*end, marker="x", ms=6, color=DEAD_COLOUR, mew=1.5, zorder=4)
    ax.plot(tx, ty, marker="*", ms=14, color=TARGET_COLOUR, mec="k", mew=0.6, zorder=TARGET_Z)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("(b) trajectories")
    ax.grid(True, lw=0.3, alpha=0.5)
    big = run.n_agents > GROUP_ABOVE
    extra = [
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker=FOLLOWER_MARKER, mfc="0.7", mec="k", label="final"),
        Line2D([], [], ls="", marker=LEADER_MARKER, ms=11, mfc="0.7", mec="k", label="leader (L), final"),
        Line2D([], [], ls="", marker="*", ms=12, color=TARGET_COLOUR, mec="k", label="target"),
        Line2D([], [], ls="--", color=EXPECTED_COLOUR, label="expected orbit"),
    ]
    if not run.alive[-1].all():
        extra.append(Line2D([], [], ls=":", marker="x", color=DEAD_COLOUR, label="dead / coasting"))
    if big if tree_legend is None else tree_legend:  # a figure legend: the layout makes room for it
        handles, ncol = tree_legend_handles(looks)
        ax.figure.legend(
            handles=handles,
            ncol=ncol,
            fontsize=size_for(run.n_agents, 7, 6),
            loc="outside right upper",
            handlelength=1.6,
            columnspacing=1.0,
            title="agents by tree",
            title_fontsize=7,
            framealpha=0.8,
        )
    key_legend(ax, extra, ncol=3)
    equal_aspect(ax)
    _label_finals(ax, ctx, finals, [j for j in finals if looks.leader[j] or not big], np.array(starts))


def equal_aspect(ax: Axes) -> None:
    """Equal scales on x and y by widening the data limits to the laid-out axes' shape
    (everything that takes room must be drawn before). Letting matplotlib do it at draw
    time ("datalim") changes the ticks after the layout has made room for them, and
    shrinking the box ("box") fights figure legends: both cut the y label."""
    w, h = axes_size_pt(ax)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    scale = max((x1 - x0) / w, (y1 - y0) / h)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    ax.set_xlim(cx - scale * w / 2, cx + scale * w / 2)
    ax.set_ylim(cy - scale * h / 2, cy + scale * h / 2)
    ax.set_aspect("equal", adjustable="box")  # the box absorbs what the final layout still changes


def _label_finals(
    ax: Axes, ctx: Ctx, finals: dict[int, tuple[float, float]], labelled: list[int], starts: np.ndarray
) -> None:
    """Labels next to the final markers, leaders first, none over another or a marker."""
    if not labelled:
        return
    labelled = sorted(labelled, key=lambda j: (not ctx.looks.leader[j], j))
    others = [finals[j] for j in finals if j not in labelled]
    obstacles = np.array(others + [tuple(ctx.run.target)] + [tuple(s) for s in starts], dtype=float).reshape(-1, 2)
    xy = np.array([finals[j] for j in labelled], dtype=float)
    fs = size_for(ctx.run.n_agents, 8, 6)
    texts = [ctx.looks.labels[j] for j in labelled]
    for j, text, (ox, oy) in zip(labelled, texts, place_point_labels(ax, xy, texts, fs, obstacles)):
        ha, va = ha_va(ox, oy)
        far = abs(ox) > 6 or abs(oy) > 6
        ax.annotate(
            text,
            finals[j],
            xytext=(ox, oy),
            textcoords="offset points",
            fontsize=fs,
            ha=ha,
            va=va,
            fontweight="bold" if ctx.looks.leader[j] else "normal",
            zorder=7,
            bbox=dict(boxstyle="round,pad=0.1", fc="white", ec=ctx.looks.colours[j], lw=0.8, alpha=0.85),
            arrowprops=dict(arrowstyle="-", color="0.3", lw=0.5, shrinkA=0, shrinkB=3) if far else None,
        )
