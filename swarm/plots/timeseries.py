"""Panels over time: (c) distance from the target with the expected radii and a tick at
every out-neighbour switch, (d) the turn-rate inputs u (y-range from clipping.py). Both
mark drops, rejoins and faults (labels side by side where events crowd) and label each
line's end with its agent's label, spread so that no two labels overlap. Each panel can
draw a subset of the agents (the small multiples of groups.py)."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.transforms import offset_copy

from swarm.plots.clipping import ControlRange, control_range, mark_clips
from swarm.plots.context import Ctx, Span
from swarm.plots.placement import axes_size_pt, spread_1d, stack_offsets
from swarm.plots.style import (
    DEAD_COLOUR,
    EVENT_COLOURS,
    EXPECTED_COLOUR,
    FAULT_COLOUR,
    SPAN_ALPHA,
    envelope,
    figure_of,
    key_legend,
    size_for,
    split_alive,
)
from swarm.world.metrics import switch_ticks
from swarm.world.run_reader import RunEvent, first_alive

MAX_EVENT_LABELS = 30
MAX_SWITCH_MARKS = 2000  # switch markers drawn on the distance plot
EVENT_FONT = 7.5  # pt: the event labels along the top
MAX_MERGED = 6  # agent ids in one merged event label


def merged(events: list[RunEvent]) -> list[RunEvent]:
    """Events of one kind at one time as one ("drop 3, 4, 5"; "+k" past MAX_MERGED ids)."""
    out: list[tuple[RunEvent, list[str]]] = []
    for ev in events:
        head, _, who = ev.label.partition(" ")
        prev = out[-1][0] if out else None
        if (
            prev is not None
            and prev.kind == ev.kind
            and abs(prev.time - ev.time) < 1e-9
            and prev.label.partition(" ")[0] == head
            and who
        ):
            out[-1][1].append(who)
        else:
            out.append((ev, [who] if who else []))
    result = []
    for ev, names in out:
        head = ev.label.partition(" ")[0]
        more = f" +{len(names) - MAX_MERGED}" if len(names) > MAX_MERGED else ""
        result.append(RunEvent(ev.time, ev.kind, " ".join([head, ", ".join(names[:MAX_MERGED])]).strip() + more))
    return result


def draw_spans(ax: Axes, spans: list[Span]) -> None:
    """A lasting fault shaded from its start to its end, in the fault colour, under the
    lines (its start keeps its event's line and label)."""
    for sp in spans:
        ax.axvspan(sp.start, sp.end, color=FAULT_COLOUR, alpha=SPAN_ALPHA, lw=0, zorder=0.5, label=f"_span {sp.label}")


def draw_events(ax: Axes, events: list[RunEvent]) -> None:
    """A vertical line per event; the first `MAX_EVENT_LABELS` labelled along the top (one
    label for events of one kind at one time), labels closer than a label's width set side
    by side to the right."""
    if not events:
        return
    events = merged(events)
    w_pt, _ = axes_size_pt(ax)
    x0, x1 = ax.get_xlim()
    kx = w_pt / max(x1 - x0, 1e-12)
    step = EVENT_FONT + 2.0
    right_edge = -1e9
    for i, ev in enumerate(events):
        colour = EVENT_COLOURS.get(ev.kind, "0.3")
        ax.axvline(ev.time, color=colour, lw=0.7, alpha=0.7, zorder=1)
        if i >= MAX_EVENT_LABELS:
            continue
        x = (ev.time - x0) * kx
        dx = max(0.0, right_edge + step - x)  # shift right past the previous label
        right_edge = x + dx
        ax.annotate(
            ev.label,
            (ev.time, 1.0),
            xycoords=ax.get_xaxis_transform(),
            xytext=(dx + 1.5, -3),
            textcoords="offset points",
            rotation=90,
            va="top",
            ha="left",
            fontsize=EVENT_FONT,
            color=colour,
            annotation_clip=True,
            zorder=3.5,
            bbox=dict(boxstyle="square,pad=0.05", fc="white", ec="none", alpha=0.8),
        )


def last_finite(values: np.ndarray) -> np.ndarray:
    """(N,): each column's last finite value, NaN for a column without one."""
    last = np.full(values.shape[1], np.nan)
    for j in range(values.shape[1]):
        fin = np.flatnonzero(np.isfinite(values[:, j]))
        if fin.size:
            last[j] = values[fin[-1], j]
    return last


def label_line_ends(ax: Axes, ctx: Ctx, values: np.ndarray, columns: list[int]) -> None:
    """Each agent's label just right of the axes, level with its line's last value, labels
    spread vertically so that none overlaps (a thin leader line to a moved one)."""
    fs = size_for(len(columns), 7, 5.5)
    _, h_pt = axes_size_pt(ax)
    y0, y1 = ax.get_ylim()
    last = last_finite(values)
    cols = [j for j in columns if np.isfinite(last[j])]
    if not cols:
        return
    want = np.clip([(last[j] - y0) / (y1 - y0) for j in cols], 0.0, 1.0)
    # within the axes' height (labels beyond it would make the layout shrink the axes), with
    # a margin for what the layout still takes from the height after this
    got = spread_1d(want, (fs + 3.0) / (0.95 * h_pt), lo=0.0, hi=1.0)
    text_at = offset_copy(ax.transAxes, fig=figure_of(ax), x=12.0, units="points")
    for j, w, g in zip(cols, want, got):
        colour = ctx.looks.colours[j] if ctx.run.alive[-1, j] else DEAD_COLOUR
        if abs(g - w) * h_pt > 1.5:  # moved: a leader line, under every label
            ax.annotate(
                "",
                (1.0, w),
                xycoords="axes fraction",
                xytext=(1.0, g),
                textcoords=text_at,
                annotation_clip=False,
                zorder=3,
                arrowprops=dict(arrowstyle="-", color=colour, lw=0.6, shrinkA=0, shrinkB=0),
            )
        ax.annotate(
            ctx.looks.labels[j],
            (1.0, g),
            xycoords=text_at,
            fontsize=fs,
            va="center",
            ha="left",
            color="k",
            fontweight="bold" if ctx.looks.leader[j] else "normal",
            annotation_clip=False,
            zorder=5,
            bbox=dict(boxstyle="round,pad=0.12", fc=colour, ec="none", alpha=0.7),
        )


def finish_time_axes(ax: Axes, ctx: Ctx, lines: np.ndarray, columns: list[int], ylabel: str, title: str) -> None:
    """What both time panels end with: the time axis, events, line-end labels (from the
    (T, N) `lines` as drawn undecimated), labels and grid. The y-limits must be set."""
    run = ctx.run
    ax.set_xlim(float(run.t[0]), float(run.t[-1]) if run.n_rows > 1 else float(run.t[0]) + 1.0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, lw=0.3, alpha=0.5)
    draw_spans(ax, spans_of(ctx, columns))
    draw_events(ax, events_of(ctx, columns))
    label_line_ends(ax, ctx, lines, columns)


def events_of(ctx: Ctx, columns: list[int]) -> list[RunEvent]:
    """The events of the agents in `columns` (all events when that is every agent)."""
    if len(columns) == ctx.run.n_agents:
        return ctx.events
    mine = {ctx.looks.labels[j].lstrip("L") for j in columns}
    return [ev for ev in ctx.events if ev.label.split()[-1] in mine or not ev.label.split()[-1].isdigit()]


def spans_of(ctx: Ctx, columns: list[int]) -> list[Span]:
    """The lasting faults of the agents in `columns`, and those that hit every agent."""
    mine = {int(ctx.run.ids[j]) for j in columns}
    return [sp for sp in ctx.spans if sp.agent is None or sp.agent in mine]


def switch_marks(ctx: Ctx, values: np.ndarray, columns: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, value, column) of every out-neighbour switch of `columns` (at most MAX_SWITCH_MARKS, evenly thinned)."""
    run = ctx.run
    ts, vs, cs = [], [], []
    for j, ks in enumerate(switch_ticks(run.out, run.alive)):
        if j in columns:
            ts.append(run.t[ks])
            vs.append(values[ks, j])
            cs.append(np.full(len(ks), j))
    t = np.concatenate(ts) if ts else np.zeros(0)
    v = np.concatenate(vs) if vs else np.zeros(0)
    c = np.concatenate(cs) if cs else np.zeros(0, np.int64)
    if t.size > MAX_SWITCH_MARKS:
        keep = np.linspace(0, t.size - 1, MAX_SWITCH_MARKS).round().astype(np.int64)
        t, v, c = t[keep], v[keep], c[keep]
    return t, v, c


def draw_switches(ax: Axes, ctx: Ctx, t: np.ndarray, v: np.ndarray, c: np.ndarray) -> None:
    """A short bar in the agent's colour at each switch; bars that would sit on each
    other (switches of several agents at the same time and place) stacked upwards."""
    w_pt, h_pt = axes_size_pt(ax)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    off = stack_offsets((t - x0) * w_pt / (x1 - x0), (v - y0) * h_pt / (y1 - y0), sep=4.0, step=7.0)
    for dx, dy in np.unique(off, axis=0):
        sel = (off[:, 0] == dx) & (off[:, 1] == dy)
        tr = offset_copy(ax.transData, fig=figure_of(ax), x=float(dx), y=float(dy), units="points")
        ax.scatter(
            t[sel],
            v[sel],
            marker="|",
            s=45,
            c=[ctx.looks.colours[int(j)] for j in c[sel]],
            lw=1.5,
            zorder=4,
            transform=tr,
        )
        ax.scatter(t[sel], v[sel], marker="|", s=60, c="k", lw=2.5, zorder=3.9, transform=tr)


def panel_distance(
    ax: Axes, ctx: Ctx, columns: list[int] | None = None, title: str = "(c) distance from target", legend: bool = True
) -> None:
    run, looks, rows = ctx.run, ctx.looks, ctx.rows
    columns = ctx.all_columns if columns is None else columns
    tx, ty = run.target
    dist = np.hypot(run.x - tx, run.y - ty)
    t = run.t[rows]
    live_all = np.full_like(dist, np.nan)
    for j in columns:
        col = run.alive[:, j]
        live, dead = split_alive(dist[:, j], col, first_alive(col))
        live_all[:, j] = live
        ax.plot(t, live[rows], color=looks.colours[j], lw=looks.width(j), zorder=2.5 if looks.leader[j] else 2)
        if np.isfinite(dead[rows]).any():
            ax.plot(t, dead[rows], color=DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
    radii = sorted(
        {
            round(float(ctx.expected[j]), 6)
            for j in columns  # a dead agent's orbit is gone
            if np.isfinite(ctx.expected[j]) and run.alive[-1, j]
        }
    )
    for r in radii:
        ax.axhline(r, color=EXPECTED_COLOUR, ls="--", lw=0.8, zorder=1)
    ax.set_ylim(bottom=0, top=max(ax.get_ylim()[1], 1.0))
    marks = switch_marks(ctx, dist, columns)
    if legend:
        extra = [
            Line2D([], [], color="0.3", lw=2.0 * looks.lw, label="leader (L)"),
            Line2D([], [], ls="--", color=EXPECTED_COLOUR, label="expected radius"),
        ]
        if any(
            first_alive(run.alive[:, j]) is not None and not run.alive[first_alive(run.alive[:, j]) :, j].all()
            for j in columns
        ):
            extra.append(Line2D([], [], ls=":", color=DEAD_COLOUR, label="dead / coasting"))
        if marks[0].size:
            extra.append(Line2D([], [], ls="", marker="|", ms=9, mew=1.6, color="0.3", label="out-neighbour switch"))
        key_legend(ax, extra)
    finish_time_axes(ax, ctx, live_all, columns, "distance from target (m)", title)
    if marks[0].size:
        draw_switches(ax, ctx, *marks)


def panel_control(
    ax: Axes,
    ctx: Ctx,
    columns: list[int] | None = None,
    title: str = "(d) control inputs",
    rng: ControlRange | None = None,
    legend: bool = True,
) -> None:
    run, looks = ctx.run, ctx.looks
    columns = ctx.all_columns if columns is None else columns
    u = np.where(run.alive, run.u, np.nan)
    tt, uu = envelope(run.t, u[:, columns], ctx.max_points)
    for k, j in enumerate(columns):
        ax.plot(tt, uu[:, k], color=looks.colours[j], lw=0.8 * looks.width(j), zorder=2.5 if looks.leader[j] else 2)
    ax.axhline(0.0, color="0.5", lw=0.5, zorder=1)
    rng = rng or control_range(run)
    ax.set_ylim(rng.lo, rng.hi)
    if legend:
        extra = [Line2D([], [], color="0.3", lw=2.0 * looks.lw, label="leader (L)")]
        if rng.clipped:
            extra.append(Line2D([], [], ls="", marker="^", ms=7, mfc="0.6", mec="k", label="clipped (beyond the axis)"))
        key_legend(ax, extra)
    finish_time_axes(ax, ctx, np.where(np.isfinite(u), np.clip(u, rng.lo, rng.hi), np.nan), columns, "u (rad/s)", title)
    mark_clips(ax, rng, looks, columns)
