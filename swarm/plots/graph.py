"""The communication graph: panel (a), the final graph (who follows whom at the end,
dead agents and agents with no path to a leader flagged, titled with the number of
switches that led there), and the dynamic graph, each follower's out-neighbour over time."""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import to_rgb
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch

from swarm.plots.context import Ctx
from swarm.plots.rows import follower_rows, margin_column
from swarm.plots.style import DEAD_COLOUR, FLAG_COLOUR, size_for
from swarm.world.run_reader import final_graph, switch_count, switch_counts

MAX_LISTED = 12  # ids listed in the graph's 'no path to a leader' note


def text_colour(face: Any) -> str:
    """Black or white, whichever reads better on `face`."""
    r, g, b = to_rgb(face)
    return "k" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "white"


def panel_graph(ax: Axes, ctx: Ctx) -> None:
    run, looks = ctx.run, ctx.looks
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
        ax.add_patch(
            FancyArrowPatch(
                pos[a],
                pos[b],
                arrowstyle="-|>",
                mutation_scale=size_for(n, 14, 8),
                shrinkA=radius_pt + 1,
                shrinkB=radius_pt + 2,
                color=DEAD_COLOUR if src_dead else "0.15",
                ls="--" if src_dead else "-",
                lw=1.0,
                connectionstyle="arc3,rad=0.08",
                zorder=2,
            )
        )
    for j, a in enumerate(run.ids):
        a = int(a)
        face = DEAD_COLOUR if a in dead else looks.colours[j]
        flagged = a in orphans
        if looks.leader[j]:  # a leader: a black ring round its node
            ax.scatter(*pos[a], s=node_s * 1.55, c="white", edgecolors="k", linewidths=2.2, zorder=2.9)
        ax.scatter(
            *pos[a],
            s=node_s,
            c=[face],
            edgecolors=FLAG_COLOUR if flagged else "k",
            linewidths=2.5 if flagged else 0.8,
            zorder=3,
        )
        ax.text(
            *pos[a],
            looks.labels[j],
            ha="center",
            va="center",
            fontsize=fs * (0.9 if looks.leader[j] else 1.0),
            zorder=4,
            color=text_colour(face),
            fontweight="bold" if looks.leader[j] else "normal",
        )
    ax.set_aspect("equal")
    ax.set_xlim(-1.3, 1.3)
    ax.set_ylim(-1.3, 1.3)
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)
    n_sw = switch_count(run)
    ax.set_title(f"(a) final communication graph, after {n_sw} switch{'es' if n_sw != 1 else ''}")
    handles = [Line2D([], [], ls="", marker="o", ms=9, mfc="0.85", mec="k", label="follower (id)")]
    if run.leaders():
        handles.insert(
            0, Line2D([], [], ls="", marker="o", ms=9, mfc="0.85", mec="k", mew=2.2, label="leader (L + id, ringed)")
        )
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
        ax.text(
            0.99,
            0.01,
            "\n".join(textwrap.wrap(f"no path to a leader ({len(listed)}): {text}", 40)),
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
            color=FLAG_COLOUR,
        )


def panel_neighbours(ax: Axes, ctx: Ctx) -> None:
    """One row per follower: bars in the colour of the out-neighbour it followed over time,
    labelled with that agent's label where the bar is wide enough; hatched red: none
    (searching, or loitering under the other rules); grey: not alive."""
    run, looks = ctx.run, ctx.looks
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
                kw = dict(color=looks.colours[index[o]] if o in index else "0.3", ec="k", lw=0.3)
            ax.barh(row, x1 - x0, left=x0, height=0.7, **kw)
            if o >= 0 and (x1 - x0) > 0.04 * span:
                face = looks.colours[index[o]] if o in index else "0.3"
                ax.text(
                    0.5 * (x0 + x1),
                    row,
                    looks.labels[index[o]] if o in index else str(o),
                    ha="center",
                    va="center",
                    fontsize=fs,
                    color=text_colour(face),
                )
    counts = switch_counts(run)
    n_sw = sum(counts)
    title = f"out-neighbour of each follower over time ({n_sw} switch{'es' if n_sw != 1 else ''})"
    follower_rows(ax, ctx, followers, float(t[0]), t_end, fs, title)
    handles = [
        Line2D(
            [],
            [],
            ls="",
            marker="s",
            ms=8,
            mfc="0.85",
            mec="k",
            label="bar: the out-neighbour followed (its colour and label; L = a leader)",
        ),
        Line2D([], [], ls="", marker="s", ms=8, mfc="white", mec=FLAG_COLOUR, label="none (searching)"),
        Line2D([], [], ls="", marker="s", ms=8, mfc=DEAD_COLOUR, mec="none", label="not alive"),
    ]
    ax.figure.legend(handles=handles, fontsize=7, loc="outside lower center", ncol=3, framealpha=0.8)
    margin_column(ax, "switches", [f"{counts[j]}" for j in followers], fs)
