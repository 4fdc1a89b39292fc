"""PNG plots of one run, laid out like the paper's Fig. 4/5.

`render_plots(run_dir)` reads ``trajectory.npz`` and ``summary.json`` from a run
directory and writes, next to them:

- ``graph.png``        (a) the final communication graph
- ``trajectories.png`` (b) x-y paths with start/final markers, target and expected orbits
- ``distance.png``     (c) distance from the target vs time, dashed expected radii
- ``control.png``      (d) turn-rate inputs u vs time
- ``overview.png``     the four panels in one 2x2 figure (paper layout)
- ``neighbours.png``   each follower's out-neighbour over time (the dynamic graph)

Out-neighbour switches are marked on the distance plot (small ticks on the lines) and
counted in the final-graph panel's title.

Leaders are drawn in blues, followers in yellows/oranges (the paper's colours),
dead agents in grey. Every agent is labelled by its id. Long runs are decimated to
at most `MAX_POINTS` points per line. Only the headless Agg backend is used.

Any problem with the input files comes out as a `PlotError` whose message names
the file.
"""

from __future__ import annotations

import json
import math
import textwrap
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle, FancyArrowPatch  # noqa: E402

from swarm.contracts.orbits import root_of  # noqa: E402
from world.metrics import switch_ticks  # noqa: E402

__all__ = ["PlotError", "RunData", "load_run", "render_plots", "MAX_POINTS", "PLOT_FILES"]

TRAJECTORY_FILE = "trajectory.npz"
SUMMARY_FILE = "summary.json"

#: Upper bound on the number of points drawn per line.
MAX_POINTS = 4000

#: Files written by `render_plots`, in the order they are returned.
PLOT_FILES = ("trajectories.png", "distance.png", "control.png", "graph.png", "overview.png", "neighbours.png")

# Array keys of trajectory.npz that the plots need (heading/speed/dt are optional).
_REQUIRED_KEYS = ("ids", "role", "target", "t", "x", "y", "u", "out", "alive")

_DEAD_COLOUR = "0.6"
_FLAG_COLOUR = "red"
_TARGET_COLOUR = "red"
_EVENT_COLOURS = {"drop": "tab:red", "rejoin": "tab:green", "fault": "tab:purple", "kill": "tab:purple"}
_EVENT_KINDS = ("drop", "rejoin", "fault")
_MAX_EVENT_LABELS = 30
_MAX_LISTED = 12  # ids listed in the graph's 'no path to a leader' note
_MAX_SWITCH_MARKS = 2000  # switch markers drawn on the distance plot
_DPI = 120


class PlotError(Exception):
    """A run directory cannot be plotted; the message names the offending file."""


# --------------------------------------------------------------------------- data


@dataclass
class RunData:
    """The arrays of one run plus its (possibly empty) summary."""

    ids: np.ndarray  # (N,) int
    role: np.ndarray  # (N,) str
    target: np.ndarray  # (2,)
    t: np.ndarray  # (T,)
    x: np.ndarray  # (T, N)
    y: np.ndarray  # (T, N)
    u: np.ndarray  # (T, N)
    out: np.ndarray  # (T, N) int
    alive: np.ndarray  # (T, N) bool
    orbit_radius: np.ndarray | None = None  # (N,) or None
    summary: dict[str, Any] = field(default_factory=dict)

    @property
    def n_agents(self) -> int:
        return int(self.ids.shape[0])

    @property
    def n_rows(self) -> int:
        return int(self.t.shape[0])

    def is_leader(self, j: int) -> bool:
        return str(self.role[j]) == "leader"


def load_run(run_dir: Path) -> RunData:
    """Read and check ``trajectory.npz`` (required) and ``summary.json`` (optional)."""
    run_dir = Path(run_dir)
    traj = run_dir / TRAJECTORY_FILE
    if not traj.is_file():
        raise PlotError(f"{traj}: no {TRAJECTORY_FILE} in run directory {run_dir}")
    try:
        with np.load(traj, allow_pickle=False) as z:
            missing = [k for k in _REQUIRED_KEYS if k not in z.files]
            if missing:
                raise PlotError(f"{traj}: malformed {TRAJECTORY_FILE}: missing array key(s) {', '.join(missing)}")
            arrays = {k: np.asarray(z[k]) for k in _REQUIRED_KEYS}
            orbit = np.asarray(z["orbit_radius"], dtype=float) if "orbit_radius" in z.files else None
    except PlotError:
        raise
    except Exception as exc:  # zipfile/pickle/value errors from a corrupt file
        raise PlotError(f"{traj}: cannot read {TRAJECTORY_FILE}: {exc}") from exc

    def bad(msg: str) -> PlotError:
        return PlotError(f"{traj}: malformed {TRAJECTORY_FILE}: {msg}")

    ids = arrays["ids"].reshape(-1)
    n = ids.shape[0]
    t = arrays["t"].reshape(-1).astype(float)
    nt = t.shape[0]
    if n == 0 or nt == 0:
        raise bad(f"empty run (N={n} agents, T={nt} rows)")
    if arrays["role"].reshape(-1).shape[0] != n:
        raise bad(f"'role' has shape {arrays['role'].shape}, expected ({n},)")
    if arrays["target"].reshape(-1).shape[0] != 2:
        raise bad(f"'target' has shape {arrays['target'].shape}, expected (2,)")
    for k in ("x", "y", "u", "out", "alive"):
        if arrays[k].shape != (nt, n):
            raise bad(f"'{k}' has shape {arrays[k].shape}, expected (T, N) = ({nt}, {n})")
    if orbit is not None and orbit.reshape(-1).shape[0] != n:
        orbit = None

    summary: dict[str, Any] = {}
    spath = run_dir / SUMMARY_FILE
    if spath.is_file():
        try:
            loaded = json.loads(spath.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise PlotError(f"{spath}: cannot read {SUMMARY_FILE}: {exc}") from exc
        if not isinstance(loaded, dict):
            raise PlotError(f"{spath}: malformed {SUMMARY_FILE}: top level is not an object")
        summary = loaded

    return RunData(
        ids=ids.astype(np.int64),
        role=arrays["role"].reshape(-1).astype(str),
        target=arrays["target"].reshape(-1).astype(float),
        t=t,
        x=arrays["x"].astype(float),
        y=arrays["y"].astype(float),
        u=arrays["u"].astype(float),
        out=arrays["out"].astype(np.int64),
        alive=arrays["alive"].astype(bool),
        orbit_radius=None if orbit is None else orbit.reshape(-1),
        summary=summary,
    )


# ------------------------------------------------------------------ helpers


def _decimation_rows(run: RunData, max_points: int) -> np.ndarray:
    """Row indices to draw: evenly spaced, plus first/last and alive transitions."""
    nt = run.n_rows
    if nt <= max_points:
        return np.arange(nt)
    base = np.linspace(0, nt - 1, max_points).round().astype(np.int64)
    # keep the rows around each alive/dead switch so segments start/end where they should
    change = np.flatnonzero(np.any(run.alive[1:] != run.alive[:-1], axis=1))
    extra = np.concatenate([change, change + 1]) if change.size <= max_points // 4 else np.empty(0, np.int64)
    return np.unique(np.concatenate([base, extra, [0, nt - 1]]))


def _envelope(t: np.ndarray, v: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Min/max envelope decimation of (T, N) data: keeps spikes a stride would drop."""
    nt = t.shape[0]
    if nt <= max_points:
        return t, v
    k = math.ceil(nt / (max_points // 2))
    nb = math.ceil(nt / k)
    pad = nb * k - nt
    vp = np.concatenate([v, np.full((pad, v.shape[1]), np.nan)]) if pad else v
    tp = np.concatenate([t, np.full(pad, t[-1])]) if pad else t
    blocks = vp.reshape(nb, k, v.shape[1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN buckets stay NaN
        lo = np.nanmin(blocks, axis=1)
        hi = np.nanmax(blocks, axis=1)
    tb = tp.reshape(nb, k)
    tt = np.empty(2 * nb)
    tt[0::2] = tb[:, 0]
    tt[1::2] = tb[:, -1]
    vv = np.empty((2 * nb, v.shape[1]))
    vv[0::2] = lo
    vv[1::2] = hi
    return tt, vv


def _agent_colours(run: RunData) -> list[Any]:
    """Leaders in shades of blue, followers in shades of yellow/orange."""
    leaders = [j for j in range(run.n_agents) if run.is_leader(j)]
    followers = [j for j in range(run.n_agents) if not run.is_leader(j)]
    colours: list[Any] = [None] * run.n_agents
    blues = plt.get_cmap("Blues")
    oranges = plt.get_cmap("YlOrBr")
    for rank, j in enumerate(leaders):
        colours[j] = blues(0.85 - 0.35 * (rank / max(1, len(leaders) - 1)))
    for rank, j in enumerate(followers):
        colours[j] = oranges(0.35 + 0.35 * (rank / max(1, len(followers) - 1)))
    return colours


def _expected_radii(run: RunData) -> list[float]:
    """Distinct expected orbit radii: summary's expected_radius, else leaders' orbit_radius."""
    radii: list[float] = []
    agents = run.summary.get("agents")
    if isinstance(agents, dict):
        for info in agents.values():
            if isinstance(info, dict):
                r = info.get("expected_radius")
                if isinstance(r, (int, float)) and math.isfinite(r) and r > 0:
                    radii.append(float(r))
    if not radii and run.orbit_radius is not None:
        radii = [float(r) for r in run.orbit_radius if math.isfinite(r) and r > 0]
    out: list[float] = []
    for r in sorted(radii):
        if not out or abs(r - out[-1]) > 1e-6 * max(1.0, r):
            out.append(r)
    return out


def _first_alive(alive_col: np.ndarray) -> int | None:
    idx = np.flatnonzero(alive_col)
    return int(idx[0]) if idx.size else None


def _last_alive(alive_col: np.ndarray) -> int | None:
    idx = np.flatnonzero(alive_col)
    return int(idx[-1]) if idx.size else None


@dataclass
class _Event:
    time: float
    kind: str
    label: str


def _events(run: RunData) -> list[_Event]:
    """drop/rejoin/fault events from summary.json (plus `faults` not already listed)."""
    out: list[_Event] = []
    seen_faults: set[tuple[float, Any]] = set()
    events = run.summary.get("events")
    dt = float(run.t[1] - run.t[0]) if run.n_rows > 1 else 0.0

    def when(ev: dict[str, Any]) -> float | None:
        tm = ev.get("time")
        if isinstance(tm, (int, float)) and math.isfinite(tm):
            return float(tm)
        tick = ev.get("tick")
        if isinstance(tick, int) and 0 <= tick < run.n_rows:
            return float(run.t[tick])
        if isinstance(tick, int):
            return float(run.t[0] + tick * dt)
        return None

    if isinstance(events, list):
        for ev in events:
            if not isinstance(ev, dict) or ev.get("kind") not in _EVENT_KINDS:
                continue
            tm = when(ev)
            if tm is None:
                continue
            agent = ev.get("agent")
            kind = str(ev["kind"])
            if kind == "fault":
                seen_faults.add((round(tm, 9), agent))
            out.append(_Event(tm, kind, f"{kind} {agent}" if agent is not None else kind))
    faults = run.summary.get("faults")
    if isinstance(faults, list):
        for ev in faults:
            if not isinstance(ev, dict):
                continue
            tm = when(ev)
            agent = ev.get("agent")
            if tm is None or (round(tm, 9), agent) in seen_faults:
                continue
            kind = str(ev.get("kind", "fault"))
            out.append(_Event(tm, "fault", f"{kind} {agent}" if agent is not None else kind))
    out.sort(key=lambda e: e.time)
    return out


def _draw_events(ax: Axes, events: list[_Event]) -> None:
    for i, ev in enumerate(events):
        colour = _EVENT_COLOURS.get(ev.kind, "0.3")
        ax.axvline(ev.time, color=colour, lw=0.7, alpha=0.7, zorder=1)
        if i < _MAX_EVENT_LABELS:
            ax.text(
                ev.time,
                0.99,
                " " + ev.label,
                transform=ax.get_xaxis_transform(),
                rotation=90,
                va="top",
                ha="right",
                fontsize=6,
                color=colour,
                clip_on=True,
            )


def _split_alive(values: np.ndarray, alive: np.ndarray, start: int | None) -> tuple[np.ndarray, np.ndarray]:
    """(alive-only, dead-only-after-first-join) copies of a column; NaN elsewhere.

    The dead copy also keeps the alive sample just before each drop so that the
    dotted part joins the solid one.
    """
    live = np.where(alive, values, np.nan)
    dead_mask = ~alive
    if start is None:
        dead_mask = np.zeros_like(dead_mask)
    else:
        dead_mask[:start] = False
        bridge = np.zeros_like(dead_mask)
        bridge[:-1] = alive[:-1] & dead_mask[1:]
        dead_mask = dead_mask | bridge
    dead = np.where(dead_mask, values, np.nan)
    return live, dead


def _title_suffix(run: RunData) -> str:
    sc = run.summary.get("scenario")
    conv = run.summary.get("converged")
    parts = []
    if sc is not None:
        parts.append(str(sc))
    if isinstance(conv, bool):
        parts.append("converged" if conv else "not converged")
    return f" ({', '.join(parts)})" if parts else ""


def _size_for(n: int, small: float, large: float) -> float:
    """Interpolate a size from `small` (few agents) to `large` (~50 agents)."""
    f = min(1.0, max(0.0, (n - 6) / 44))
    return small + (large - small) * f


# ------------------------------------------------------------------ panels


def _panel_trajectories(ax: Axes, run: RunData, rows: np.ndarray, colours: list[Any]) -> None:
    tx, ty = run.target
    for r in _expected_radii(run):
        ax.add_patch(Circle((tx, ty), r, fill=False, ls="--", lw=0.9, ec="0.35", zorder=1))
    fs = _size_for(run.n_agents, 8, 5)
    for j in range(run.n_agents):
        col = run.alive[:, j]
        first, last = _first_alive(col), _last_alive(col)
        live_x, dead_x = _split_alive(run.x[:, j], col, first)
        live_y, dead_y = _split_alive(run.y[:, j], col, first)
        ax.plot(live_x[rows], live_y[rows], color=colours[j], lw=1.0, zorder=2)
        if np.isfinite(dead_x[rows]).any():
            ax.plot(dead_x[rows], dead_y[rows], color=_DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
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
                color=colours[j] if alive_end else _DEAD_COLOUR,
                mec="k" if alive_end else _DEAD_COLOUR,
                mew=0.5 if alive_end else 1.5,
                zorder=4,
            )
            ax.annotate(
                str(run.ids[j]),
                (fx, fy),
                xytext=(4, 4),
                textcoords="offset points",
                fontsize=fs,
                zorder=5,
            )
    ax.plot(tx, ty, marker="*", ms=14, color=_TARGET_COLOUR, mec="k", mew=0.6, zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("(b) trajectories")
    ax.grid(True, lw=0.3, alpha=0.5)
    handles = [
        Line2D([], [], color=_agent_colours_role(run, True), lw=1.5, label="leader"),
        Line2D([], [], color=_agent_colours_role(run, False), lw=1.5, label="follower"),
        Line2D([], [], ls="", marker="o", mfc="white", mec="k", label="start"),
        Line2D([], [], ls="", marker="^", color="0.5", mec="k", label="final"),
        Line2D([], [], ls="", marker="*", ms=12, color=_TARGET_COLOUR, mec="k", label="target"),
        Line2D([], [], ls="--", color="0.35", label="expected orbit"),
    ]
    if not run.alive[-1].all():
        handles.append(Line2D([], [], ls=":", marker="x", color=_DEAD_COLOUR, label="dead / coasting"))
    _role_filter(run, handles)
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.8)


def _agent_colours_role(run: RunData, leader: bool) -> Any:
    return plt.get_cmap("Blues")(0.8) if leader else plt.get_cmap("YlOrBr")(0.5)


def _role_filter(run: RunData, handles: list[Line2D]) -> None:
    """Drop the leader/follower legend entry of a role absent from the run."""
    roles = {str(r) for r in run.role}
    handles[:] = [h for h in handles if h.get_label() not in ("leader", "follower") or h.get_label() in roles]


def _label_line_ends(ax: Axes, t_end: float, values: np.ndarray, run: RunData, colours: list[Any]) -> None:
    """Put each agent's id at the right end of its line (last finite value)."""
    fs = _size_for(run.n_agents, 7, 5)
    for j in range(run.n_agents):
        v = values[:, j]
        idx = np.flatnonzero(np.isfinite(v))
        if not idx.size:
            continue
        colour = colours[j] if run.alive[-1, j] else _DEAD_COLOUR
        ax.annotate(
            str(run.ids[j]),
            (t_end, v[idx[-1]]),
            xytext=(3, 0),
            textcoords="offset points",
            fontsize=fs,
            va="center",
            color="k",
            bbox=dict(boxstyle="round,pad=0.1", fc=colour, ec="none", alpha=0.6),
            annotation_clip=False,
        )


def _panel_distance(
    ax: Axes, run: RunData, rows: np.ndarray, colours: list[Any], events: list[_Event]
) -> None:
    tx, ty = run.target
    dist = np.hypot(run.x - tx, run.y - ty)
    t = run.t[rows]
    last_vals = np.full((1, run.n_agents), np.nan)
    for j in range(run.n_agents):
        col = run.alive[:, j]
        first = _first_alive(col)
        live, dead = _split_alive(dist[:, j], col, first)
        ax.plot(t, live[rows], color=colours[j], lw=1.0, zorder=2)
        if np.isfinite(dead[rows]).any():
            ax.plot(t, dead[rows], color=_DEAD_COLOUR, lw=0.8, ls=":", zorder=2)
        fin = np.flatnonzero(np.isfinite(live))
        if fin.size:
            last_vals[0, j] = live[fin[-1]]
    for r in _expected_radii(run):
        ax.axhline(r, color="0.35", ls="--", lw=0.9, zorder=1)
    marks = _switch_marks(run, dist)
    if marks[0].size:
        ax.scatter(marks[0], marks[1], marker="|", s=40, c="k", lw=0.8, zorder=3)
    _draw_events(ax, events)
    _label_line_ends(ax, float(run.t[-1]), last_vals, run, colours)
    ax.set_xlim(float(run.t[0]), float(run.t[-1]) if run.n_rows > 1 else float(run.t[0]) + 1.0)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("distance from target (m)")
    ax.set_title("(c) distance from target")
    ax.grid(True, lw=0.3, alpha=0.5)
    handles = [
        Line2D([], [], color=_agent_colours_role(run, True), lw=1.5, label="leader"),
        Line2D([], [], color=_agent_colours_role(run, False), lw=1.5, label="follower"),
        Line2D([], [], ls="--", color="0.35", label="expected radius"),
    ]
    if not run.alive[-1].all():
        handles.append(Line2D([], [], ls=":", color=_DEAD_COLOUR, label="dead / coasting"))
    if marks[0].size:
        handles.append(Line2D([], [], ls="", marker="|", color="k", label="out-neighbour switch"))
    _role_filter(run, handles)
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.8)


def _switch_marks(run: RunData, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, value) of every out-neighbour switch (at most _MAX_SWITCH_MARKS, evenly thinned)."""
    ts, vs = [], []
    for j, ks in enumerate(switch_ticks(run.out, run.alive)):
        ts.append(run.t[ks])
        vs.append(values[ks, j])
    t = np.concatenate(ts) if ts else np.zeros(0)
    v = np.concatenate(vs) if vs else np.zeros(0)
    if t.size > _MAX_SWITCH_MARKS:
        keep = np.linspace(0, t.size - 1, _MAX_SWITCH_MARKS).round().astype(np.int64)
        t, v = t[keep], v[keep]
    return t, v


def switch_count(run: RunData) -> int:
    """Out-neighbour changes of all agents while alive (summary.json's `switches`)."""
    return int(sum(len(k) for k in switch_ticks(run.out, run.alive)))


def _panel_neighbours(ax: Axes, run: RunData, colours: list[Any]) -> None:
    """One row per follower: bars coloured by the out-neighbour it followed over time,
    labelled with that id where the bar is wide enough; hatched red: none (loitering);
    grey: not alive."""
    followers = [j for j in range(run.n_agents) if not run.is_leader(j)]
    index = {int(a): j for j, a in enumerate(run.ids)}
    t = run.t
    t_end = float(t[-1]) + (float(t[1] - t[0]) if run.n_rows > 1 else 1.0)
    span = max(t_end - float(t[0]), 1e-9)
    fs = _size_for(run.n_agents, 7, 5)
    for row, j in enumerate(followers):
        state = np.where(run.alive[:, j], run.out[:, j], -2)  # -2: not alive, -1: none
        starts = np.concatenate([[0], np.flatnonzero(state[1:] != state[:-1]) + 1])
        ends = np.concatenate([starts[1:], [run.n_rows]])
        for a, b in zip(starts, ends):
            x0 = float(t[a])
            x1 = float(t[b]) if b < run.n_rows else t_end
            o = int(state[a])
            if o == -2:
                kw: dict[str, Any] = dict(color=_DEAD_COLOUR, alpha=0.35)
            elif o == -1:
                kw = dict(facecolor="white", edgecolor=_FLAG_COLOUR, hatch="////", lw=0.0)
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
    counts = [len(k) for k in switch_ticks(run.out, run.alive)]
    ax.set_title(f"out-neighbour of each follower over time ({sum(counts)} switches)")
    ax.grid(True, axis="x", lw=0.3, alpha=0.5)
    handles = [Line2D([], [], ls="", marker="s", ms=8, mfc=_agent_colours_role(run, True), mec="k",
                      label="a leader (bar text: its id)"),
               Line2D([], [], ls="", marker="s", ms=8, mfc=_agent_colours_role(run, False), mec="k",
                      label="a follower"),
               Line2D([], [], ls="", marker="s", ms=8, mfc="white", mec=_FLAG_COLOUR, label="none (loitering)"),
               Line2D([], [], ls="", marker="s", ms=8, mfc=_DEAD_COLOUR, mec="none", label="not alive")]
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18 - 0.5 / max(len(followers), 1)),
              ncol=4, framealpha=0.8)
    ax.annotate("switches", (1.0, 1.0), xycoords="axes fraction", xytext=(3, 2), textcoords="offset points",
                va="bottom", fontsize=fs, color="0.3")
    for k, j in enumerate(followers):
        ax.annotate(f"{counts[j]}", (1.0, k), xycoords=("axes fraction", "data"), xytext=(3, 0),
                    textcoords="offset points", va="center", fontsize=fs, color="0.3")


def _panel_control(ax: Axes, run: RunData, colours: list[Any], events: list[_Event], max_points: int) -> None:
    u = np.where(run.alive, run.u, np.nan)
    tt, uu = _envelope(run.t, u, max_points)
    for j in range(run.n_agents):
        ax.plot(tt, uu[:, j], color=colours[j], lw=0.8, zorder=2)
    last_vals = np.full((1, run.n_agents), np.nan)
    for j in range(run.n_agents):
        fin = np.flatnonzero(np.isfinite(u[:, j]))
        if fin.size:
            last_vals[0, j] = u[fin[-1], j]
    ax.axhline(0.0, color="0.5", lw=0.5, zorder=1)
    _draw_events(ax, events)
    _label_line_ends(ax, float(run.t[-1]), last_vals, run, colours)
    ax.set_xlim(float(run.t[0]), float(run.t[-1]) if run.n_rows > 1 else float(run.t[0]) + 1.0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("u (rad/s)")
    ax.set_title("(d) control inputs")
    ax.grid(True, lw=0.3, alpha=0.5)
    handles = [
        Line2D([], [], color=_agent_colours_role(run, True), lw=1.5, label="leader"),
        Line2D([], [], color=_agent_colours_role(run, False), lw=1.5, label="follower"),
    ]
    _role_filter(run, handles)
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.8)


def final_graph(run: RunData) -> tuple[dict[int, int], set[int], set[int]]:
    """The final communication graph.

    Returns (edges, dead, orphans): ``edges[i] = j`` for agent id i whose out-neighbour
    at its last alive row was id j; ``dead`` = ids not alive in the last row;
    ``orphans`` = live ids with no path along out-edges through live agents to a live
    leader.
    """
    index = {int(a): j for j, a in enumerate(run.ids)}
    edges: dict[int, int] = {}
    for j, a in enumerate(run.ids):
        last = _last_alive(run.alive[:, j])
        if last is None:
            continue
        o = int(run.out[last, j])
        if o >= 0 and o in index and o != int(a):
            edges[int(a)] = o
    alive_end = {int(a) for j, a in enumerate(run.ids) if run.alive[-1, j]}
    dead = {int(a) for a in run.ids} - alive_end
    leaders = {int(a) for j, a in enumerate(run.ids) if run.is_leader(j)}
    live_out = {a: edges.get(a) for a in alive_end}  # walks end at dead agents
    orphans = {a for a in alive_end if root_of(a, live_out, leaders & alive_end)[0] is None}
    return edges, dead, orphans


def _panel_graph(ax: Axes, run: RunData, colours: list[Any]) -> None:
    n = run.n_agents
    edges, dead, orphans = final_graph(run)
    # nodes on a circle, first agent at the top, clockwise in scenario order
    ang = math.pi / 2 - 2 * math.pi * np.arange(n) / n
    pos = {int(a): (math.cos(ang[j]), math.sin(ang[j])) for j, a in enumerate(run.ids)}
    if n == 1:
        pos = {int(run.ids[0]): (0.0, 0.0)}
    node_s = _size_for(n, 700, 170)
    radius_pt = math.sqrt(node_s) / 2
    fs = _size_for(n, 10, 6)
    for a, b in edges.items():
        src_dead = a in dead or b in dead
        ax.add_patch(
            FancyArrowPatch(
                pos[a],
                pos[b],
                arrowstyle="-|>",
                mutation_scale=_size_for(n, 14, 8),
                shrinkA=radius_pt + 1,
                shrinkB=radius_pt + 2,
                color=_DEAD_COLOUR if src_dead else "0.15",
                ls="--" if src_dead else "-",
                lw=1.0,
                connectionstyle="arc3,rad=0.08",
                zorder=2,
            )
        )
    for j, a in enumerate(run.ids):
        a = int(a)
        face = _DEAD_COLOUR if a in dead else colours[j]
        flagged = a in orphans
        ax.scatter(
            *pos[a],
            s=node_s,
            c=[face],
            edgecolors=_FLAG_COLOUR if flagged else "k",
            linewidths=2.5 if flagged else 0.8,
            zorder=3,
        )
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
    roles = {str(r) for r in run.role}
    handles = []
    if "leader" in roles:
        handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc=_agent_colours_role(run, True), mec="k", label="leader"))
    if "follower" in roles:
        handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc=_agent_colours_role(run, False), mec="k", label="follower"))
    if dead:
        handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc=_DEAD_COLOUR, mec="k", label="dead"))
    if orphans:
        handles.append(
            Line2D([], [], ls="", marker="o", ms=9, mfc="white", mec=_FLAG_COLOUR, mew=2.5, label="no path to a leader")
        )
    handles.append(Line2D([], [], color="0.15", marker=">", ms=5, label="i → out-neighbour"))
    ax.legend(handles=handles, fontsize=7, loc="lower left", framealpha=0.8)
    if orphans:
        listed = sorted(orphans)
        text = ", ".join(str(a) for a in listed[:_MAX_LISTED])
        if len(listed) > _MAX_LISTED:
            text += f", … (+{len(listed) - _MAX_LISTED} more)"
        ax.text(
            0.99,
            0.01,
            "\n".join(textwrap.wrap(f"no path to a leader ({len(listed)}): {text}", 40)),
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
            color=_FLAG_COLOUR,
        )


# ------------------------------------------------------------------ entry point


def _save(fig: Any, path: Path) -> None:
    try:
        fig.savefig(path, dpi=_DPI)
    finally:
        plt.close(fig)


def render_plots(run_dir: Path, max_points: int = MAX_POINTS) -> list[Path]:
    """Write the run's PNG plots into `run_dir`; return their paths (see `PLOT_FILES`)."""
    run_dir = Path(run_dir)
    run = load_run(run_dir)
    max_points = max(16, int(max_points))
    rows = _decimation_rows(run, max_points)
    colours = _agent_colours(run)
    events = _events(run)
    suffix = _title_suffix(run)
    paths = [run_dir / name for name in PLOT_FILES]
    p_traj, p_dist, p_ctrl, p_graph, p_over, p_nb = paths

    fig, ax = plt.subplots(figsize=(7.5, 7), layout="constrained")
    _panel_trajectories(ax, run, rows, colours)
    ax.set_title(ax.get_title() + suffix)
    _save(fig, p_traj)

    fig, ax = plt.subplots(figsize=(9, 5), layout="constrained")
    _panel_distance(ax, run, rows, colours, events)
    ax.set_title(ax.get_title() + suffix)
    _save(fig, p_dist)

    fig, ax = plt.subplots(figsize=(9, 5), layout="constrained")
    _panel_control(ax, run, colours, events, max_points)
    ax.set_title(ax.get_title() + suffix)
    _save(fig, p_ctrl)

    fig, ax = plt.subplots(figsize=(7, 7), layout="constrained")
    _panel_graph(ax, run, colours)
    ax.set_title(ax.get_title() + suffix)
    _save(fig, p_graph)

    fig, axs = plt.subplots(2, 2, figsize=(14, 12), layout="constrained")
    _panel_graph(axs[0, 0], run, colours)
    _panel_trajectories(axs[0, 1], run, rows, colours)
    _panel_distance(axs[1, 0], run, rows, colours, events)
    _panel_control(axs[1, 1], run, colours, events, max_points)
    fig.suptitle("Run overview" + suffix)
    _save(fig, p_over)

    n_f = sum(1 for j in range(run.n_agents) if not run.is_leader(j))
    fig, ax = plt.subplots(figsize=(10, 1.9 + 0.35 * max(n_f, 1)), layout="constrained")
    _panel_neighbours(ax, run, colours)
    ax.set_title(ax.get_title() + suffix)
    _save(fig, p_nb)

    return paths
