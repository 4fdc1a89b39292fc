"""Panel (b): x-y paths with start/final markers, the target and the expected orbits."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from swarm.plots.style import DEAD_COLOUR, EXPECTED_COLOUR, TARGET_COLOUR, role_legend, size_for, split_alive
from world.run_reader import RunData, expected_radii, first_alive, last_alive


def panel_trajectories(ax: Axes, run: RunData, rows: np.ndarray, colours: list[Any]) -> None:
    tx, ty = run.target
    for r in expected_radii(run):
        ax.add_patch(Circle((tx, ty), r, fill=False, ls="--", lw=0.9, ec=EXPECTED_COLOUR, zorder=1))
    fs = size_for(run.n_agents, 8, 5)
    for j in range(run.n_agents):
        col = run.alive[:, j]
        first, last = first_alive(col), last_alive(col)
        live_x, dead_x = split_alive(run.x[:, j], col, first)
        live_y, dead_y = split_alive(run.y[:, j], col, first)
        ax.plot(live_x[rows], live_y[rows], color=colours[j], lw=1.0, zorder=2)
        if np.isfinite(dead_x[rows]).any():
            ax.plot(dead_x[rows], dead_y[rows], color=DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
        s = first if first is not None else 0
        if np.isfinite(run.x[s, j]) and np.isfinite(run.y[s, j]):
            ax.plot(run.x[s, j], run.y[s, j], marker="o", ms=4, mfc="white", mec=colours[j], zorder=3)
        # final position: last row; grey cross if the agent is not alive at the end
        fx, fy = run.x[-1, j], run.y[-1, j]
        if not (np.isfinite(fx) and np.isfinite(fy)) and last is not None:
            fx, fy = run.x[last, j], run.y[last, j]
        if np.isfinite(fx) and np.isfinite(fy):
            alive_end = bool(col[-1])
            ax.plot(
                fx,
                fy,
                marker="^" if alive_end else "x",
                ms=6,
                color=colours[j] if alive_end else DEAD_COLOUR,
                mec="k" if alive_end else DEAD_COLOUR,
                mew=0.5 if alive_end else 1.5,
                zorder=4,
            )
            ax.annotate(str(run.ids[j]), (fx, fy), xytext=(4, 4), textcoords="offset points", fontsize=fs, zorder=5)
    ax.plot(tx, ty, marker="*", ms=14, color=TARGET_COLOUR, mec="k", mew=0.6, zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("(b) trajectories")
    ax.grid(True, lw=0.3, alpha=0.5)
    extra = [
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker="^", color="0.5", mec="k", label="final"),
        Line2D([], [], ls="", marker="*", ms=12, color=TARGET_COLOUR, mec="k", label="target"),
        Line2D([], [], ls="--", color=EXPECTED_COLOUR, label="expected orbit"),
    ]
    if not run.alive[-1].all():
        extra.append(Line2D([], [], ls=":", marker="x", color=DEAD_COLOUR, label="dead / coasting"))
    role_legend(ax, run, extra)
