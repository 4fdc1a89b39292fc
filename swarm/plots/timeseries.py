"""Panels over time: (c) distance from the target with the expected radii and a tick at
every out-neighbour switch, (d) the turn-rate inputs u. Both mark drops, rejoins and
faults and label each line's end with its agent's id."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D

from swarm.plots.style import (
    DEAD_COLOUR,
    EVENT_COLOURS,
    EXPECTED_COLOUR,
    envelope,
    role_legend,
    size_for,
    split_alive,
)
from world.metrics import switch_ticks
from world.run_reader import RunData, RunEvent, expected_radii, first_alive

MAX_EVENT_LABELS = 30
MAX_SWITCH_MARKS = 2000  # switch markers drawn on the distance plot


def draw_events(ax: Axes, events: list[RunEvent]) -> None:
    """A vertical line per event, the first `MAX_EVENT_LABELS` labelled."""
    for i, ev in enumerate(events):
        colour = EVENT_COLOURS.get(ev.kind, "0.3")
        ax.axvline(ev.time, color=colour, lw=0.7, alpha=0.7, zorder=1)
        if i < MAX_EVENT_LABELS:
            ax.text(ev.time, 0.99, " " + ev.label, transform=ax.get_xaxis_transform(), rotation=90, va="top",
                    ha="right", fontsize=6, color=colour, clip_on=True)


def last_finite(values: np.ndarray) -> np.ndarray:
    """(1, N): each column's last finite value, NaN for a column without one."""
    last = np.full((1, values.shape[1]), np.nan)
    for j in range(values.shape[1]):
        fin = np.flatnonzero(np.isfinite(values[:, j]))
        if fin.size:
            last[0, j] = values[fin[-1], j]
    return last


def label_line_ends(ax: Axes, t_end: float, values: np.ndarray, run: RunData, colours: list[Any]) -> None:
    """Put each agent's id at the right end of its line (last finite value)."""
    fs = size_for(run.n_agents, 7, 5)
    for j in range(run.n_agents):
        v = values[:, j]
        idx = np.flatnonzero(np.isfinite(v))
        if not idx.size:
            continue
        colour = colours[j] if run.alive[-1, j] else DEAD_COLOUR
        ax.annotate(str(run.ids[j]), (t_end, v[idx[-1]]), xytext=(3, 0), textcoords="offset points", fontsize=fs,
                    va="center", color="k", bbox=dict(boxstyle="round,pad=0.1", fc=colour, ec="none", alpha=0.6),
                    annotation_clip=False)


def finish_time_axes(ax: Axes, run: RunData, colours: list[Any], events: list[RunEvent], lines: np.ndarray,
                     ylabel: str, title: str) -> None:
    """What both time panels end with: events, line-end labels (from the (T, N) `lines`
    as drawn undecimated), the time axis, labels and grid."""
    draw_events(ax, events)
    label_line_ends(ax, float(run.t[-1]), last_finite(lines), run, colours)
    ax.set_xlim(float(run.t[0]), float(run.t[-1]) if run.n_rows > 1 else float(run.t[0]) + 1.0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, lw=0.3, alpha=0.5)


def switch_marks(run: RunData, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, value) of every out-neighbour switch (at most MAX_SWITCH_MARKS, evenly thinned)."""
    ts, vs = [], []
    for j, ks in enumerate(switch_ticks(run.out, run.alive)):
        ts.append(run.t[ks])
        vs.append(values[ks, j])
    t = np.concatenate(ts) if ts else np.zeros(0)
    v = np.concatenate(vs) if vs else np.zeros(0)
    if t.size > MAX_SWITCH_MARKS:
        keep = np.linspace(0, t.size - 1, MAX_SWITCH_MARKS).round().astype(np.int64)
        t, v = t[keep], v[keep]
    return t, v


def panel_distance(ax: Axes, run: RunData, rows: np.ndarray, colours: list[Any], events: list[RunEvent]) -> None:
    tx, ty = run.target
    dist = np.hypot(run.x - tx, run.y - ty)
    t = run.t[rows]
    live_all = np.full_like(dist, np.nan)
    for j in range(run.n_agents):
        col = run.alive[:, j]
        live, dead = split_alive(dist[:, j], col, first_alive(col))
        live_all[:, j] = live
        ax.plot(t, live[rows], color=colours[j], lw=1.0, zorder=2)
        if np.isfinite(dead[rows]).any():
            ax.plot(t, dead[rows], color=DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
    for r in expected_radii(run):
        ax.axhline(r, color=EXPECTED_COLOUR, ls="--", lw=0.9, zorder=1)
    marks = switch_marks(run, dist)
    if marks[0].size:
        ax.scatter(marks[0], marks[1], marker="|", s=40, c="k", lw=0.8, zorder=3)
    finish_time_axes(ax, run, colours, events, live_all, "distance from target (m)", "(c) distance from target")
    ax.set_ylim(bottom=0)
    extra = [Line2D([], [], ls="--", color=EXPECTED_COLOUR, label="expected radius")]
    if not run.alive[-1].all():
        extra.append(Line2D([], [], ls=":", color=DEAD_COLOUR, label="dead / coasting"))
    if marks[0].size:
        extra.append(Line2D([], [], ls="", marker="|", color="k", label="out-neighbour switch"))
    role_legend(ax, run, extra)


def panel_control(ax: Axes, run: RunData, colours: list[Any], events: list[RunEvent], max_points: int) -> None:
    u = np.where(run.alive, run.u, np.nan)
    tt, uu = envelope(run.t, u, max_points)
    for j in range(run.n_agents):
        ax.plot(tt, uu[:, j], color=colours[j], lw=0.8, zorder=2)
    ax.axhline(0.0, color="0.5", lw=0.5, zorder=1)
    finish_time_axes(ax, run, colours, events, u, "u (rad/s)", "(d) control inputs")
    role_legend(ax, run, [])
