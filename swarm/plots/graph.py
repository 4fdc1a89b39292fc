"""The communication graph: panel (a), the final graph (who follows whom at the end,
dead agents and agents with no path to a leader flagged, titled with the number of
switches that led there), and the dynamic graph, each follower's out-neighbour over time."""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch

from swarm.plots.style import DEAD_COLOUR, FLAG_COLOUR, role_colour, role_handles, size_for
from world.run_reader import RunData, final_graph, switch_count, switch_counts

MAX_LISTED = 12  # ids listed in the graph's 'no path to a leader' note


def panel_graph(ax: Axes, run: RunData, colours: list[Any]) -> None:
    n = run.n_agents
    edges, dead, orphans = final_graph(run)
    # nodes on a circle, first agent at the top, clockwise in scenario order
    ang = math.pi / 2 - 2 * math.pi * np.arange(n) / n
    pos = {int(a): (math.cos(ang[j]), math.sin(ang[j])) for j, a in enumerate(run.ids)}
    if n == 1:
        pos = {int(run.ids[0]): (0.0, 0.0)}
    node_s = size_for(n, 700, 170)
    radius_pt = math.sqrt(node_s) / 2
    fs = size_for(n, 10, 6)
    for a, b in edges.items():
        src_dead = a in dead or b in dead
        ax.add_patch(FancyArrowPatch(
            pos[a], pos[b], arrowstyle="-|>", mutation_scale=size_for(n, 14, 8), shrinkA=radius_pt + 1,
            shrinkB=radius_pt + 2, color=DEAD_COLOUR if src_dead else "0.15", ls="--" if src_dead else "-", lw=1.0,
            connectionstyle="arc3,rad=0.08", zorder=2,
        ))
    for j, a in enumerate(run.ids):
        a = int(a)
        face = DEAD_COLOUR if a in dead else colours[j]
        flagged = a in orphans
        ax.scatter(*pos[a], s=node_s, c=[face], edgecolors=FLAG_COLOUR if flagged else "k",
                   linewidths=2.5 if flagged else 0.8, zorder=3)
        ax.text(*pos[a], str(a), ha="center", va="center", fontsize=fs, zorder=4,
                color="white" if (run.is_leader(j) and a not in dead) else "k")
    ax.set_aspect("equal")
    ax.set_xlim(-1.3, 1.3)
    ax.set_ylim(-1.3, 1.3)
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)
    n_sw = switch_count(run)
    ax.set_title(f"(a) final communication graph, after {n_sw} switch{'es' if n_sw != 1 else ''}")
    handles = role_handles(run, ls="", marker="o", ms=9, mec="k")
    if dead:
        handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc=DEAD_COLOUR, mec="k", label="dead"))
    if orphans:
        handles.append(
            Line2D([], [], ls="", marker="o", ms=9, mfc="white", mec=FLAG_COLOUR, mew=2.5, label="no path to a leader")
        )
    handles.append(Line2D([], [], color="0.15", marker=">", ms=5, label="i → out-neighbour"))
    ax.legend(handles=handles, fontsize=7, loc="lower left", framealpha=0.8)
    if orphans:
        listed = sorted(orphans)
        text = ", ".join(str(a) for a in listed[:MAX_LISTED])
        if len(listed) > MAX_LISTED:
            text += f", … (+{len(listed) - MAX_LISTED} more)"
        ax.text(0.99, 0.01, "\n".join(textwrap.wrap(f"no path to a leader ({len(listed)}): {text}", 40)),
                transform=ax.transAxes, ha="right", va="bottom", fontsize=7, color=FLAG_COLOUR)


def panel_neighbours(ax: Axes, run: RunData, colours: list[Any]) -> None:
    """One row per follower: bars coloured by the out-neighbour it followed over time,
    labelled with that id where the bar is wide enough; hatched red: none (loitering);
    grey: not alive."""
    followers = run.followers()
    index = run.column_of()
    t = run.t
    t_end = float(t[-1]) + (float(t[1] - t[0]) if run.n_rows > 1 else 1.0)
    span = max(t_end - float(t[0]), 1e-9)
    fs = size_for(run.n_agents, 7, 5)
    for row, j in enumerate(followers):
        state = np.where(run.alive[:, j], run.out[:, j], -2)  # -2: not alive, -1: none
        starts = np.concatenate([[0], np.flatnonzero(state[1:] != state[:-1]) + 1])
        ends = np.concatenate([starts[1:], [run.n_rows]])
        for a, b in zip(starts, ends):
            x0 = float(t[a])
            x1 = float(t[b]) if b < run.n_rows else t_end
            o = int(state[a])
            if o == -2:
                kw: dict[str, Any] = dict(color=DEAD_COLOUR, alpha=0.35)
            elif o == -1:
                kw = dict(facecolor="white", edgecolor=FLAG_COLOUR, hatch="////", lw=0.0)
            else:
                kw = dict(color=colours[index[o]] if o in index else "0.3", ec="k", lw=0.3)
            ax.barh(row, x1 - x0, left=x0, height=0.7, **kw)
            if o >= 0 and (x1 - x0) > 0.04 * span:
                ax.text(0.5 * (x0 + x1), row, str(o), ha="center", va="center", fontsize=fs)
    ax.set_yticks(range(len(followers)), [str(int(run.ids[j])) for j in followers], fontsize=fs)
    ax.set_ylim(len(followers) - 0.5, -0.5)
    ax.set_xlim(float(t[0]), t_end)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("follower")
    counts = switch_counts(run)
    ax.set_title(f"out-neighbour of each follower over time ({sum(counts)} switches)")
    ax.grid(True, axis="x", lw=0.3, alpha=0.5)
    handles = [Line2D([], [], ls="", marker="s", ms=8, mfc=role_colour(True), mec="k",
                      label="a leader (bar text: its id)"),
               Line2D([], [], ls="", marker="s", ms=8, mfc=role_colour(False), mec="k", label="a follower"),
               Line2D([], [], ls="", marker="s", ms=8, mfc="white", mec=FLAG_COLOUR, label="none (loitering)"),
               Line2D([], [], ls="", marker="s", ms=8, mfc=DEAD_COLOUR, mec="none", label="not alive")]
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18 - 0.5 / max(len(followers), 1)),
              ncol=4, framealpha=0.8)
    ax.annotate("switches", (1.0, 1.0), xycoords="axes fraction", xytext=(3, 2), textcoords="offset points",
                va="bottom", fontsize=fs, color="0.3")
    for k, j in enumerate(followers):
        ax.annotate(f"{counts[j]}", (1.0, k), xycoords=("axes fraction", "data"), xytext=(3, 0),
                    textcoords="offset points", va="center", fontsize=fs, color="0.3")
