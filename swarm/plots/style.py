"""What every panel shares: fixed colours and sizes, the key legend under an axes, and
how long runs are thinned for drawing (row decimation for lines, min/max envelope for
spiky inputs). Each agent's own colour, label and width: palette.py. Dead agents: grey.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.transforms import offset_copy

from swarm.contracts.vocabulary import EventKind
from swarm.world.run_reader import RunData

#: Upper bound on the number of points drawn per line.
MAX_POINTS = 4000

DEAD_COLOUR = "0.6"
FLAG_COLOUR = "red"
TARGET_COLOUR = "red"
EXPECTED_COLOUR = "0.35"  # dashed expected orbits / radii
#: Faults (and kills): magenta, a colour no agent has (palette.py's maps hold no pure
#: magenta; the nearest of their 54 colours is 0.45 away in RGB).
FAULT_COLOUR = "#e000e0"
EVENT_COLOURS = {
    EventKind.DROP: "tab:red",
    EventKind.REJOIN: "tab:green",
    EventKind.FAULT: FAULT_COLOUR,
    "kill": FAULT_COLOUR,
}
SPAN_ALPHA = 0.12  # a lasting fault's shading, from its start to its end
DPI = 120
KEY_DROP_PT = 34.0  # the key legend's top, this far under the axes (below tick labels and x label)


def figure_of(ax: Axes) -> Figure:
    """The figure `ax` is drawn in (these plots make no subfigures: it is the root one)."""
    fig = ax.get_figure(root=True)
    if fig is None:
        raise ValueError("axes that belong to no figure")
    return fig


def size_for(n: int, small: float, large: float) -> float:
    """Interpolate a size from `small` (few agents) to `large` (~50 agents)."""
    f = min(1.0, max(0.0, (n - 6) / 44))
    return small + (large - small) * f


def key_legend(ax: Axes, handles: list[Line2D], ncol: int | None = None, **kw: Any) -> None:
    """The legend of what the marks mean, under the axes (clear of lines and labels)."""
    if not handles:
        return
    below = offset_copy(ax.transAxes, fig=figure_of(ax), y=-KEY_DROP_PT, units="points")  # under the x label
    ax.legend(
        handles=handles,
        fontsize=7,
        loc="upper center",
        bbox_to_anchor=(0.5, 0.0),
        bbox_transform=below,
        ncol=ncol or min(len(handles), 4),
        framealpha=0.8,
        **kw,
    )


def decimation_rows(run: RunData, max_points: int) -> np.ndarray:
    """Row indices to draw: evenly spaced, plus first/last and alive transitions."""
    nt = run.n_rows
    if nt <= max_points:
        return np.arange(nt)
    base = np.linspace(0, nt - 1, max_points).round().astype(np.int64)
    # keep the rows around each alive/dead switch so segments start/end where they should
    change = np.flatnonzero(np.any(run.alive[1:] != run.alive[:-1], axis=1))
    extra = np.concatenate([change, change + 1]) if change.size <= max_points // 4 else np.empty(0, np.int64)
    return np.unique(np.concatenate([base, extra, [0, nt - 1]]))


def envelope(t: np.ndarray, v: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
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


def split_alive(values: np.ndarray, alive: np.ndarray, start: int | None) -> tuple[np.ndarray, np.ndarray]:
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
