"""What every panel shares: colours, sizes, the legend of the roles, and how long runs
are thinned for drawing (row decimation for lines, min/max envelope for spiky inputs).

Leaders are drawn in blues, followers in yellows/oranges (the paper's colours), dead
agents in grey.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D

from world.run_reader import RunData

#: Upper bound on the number of points drawn per line.
MAX_POINTS = 4000

DEAD_COLOUR = "0.6"
FLAG_COLOUR = "red"
TARGET_COLOUR = "red"
EXPECTED_COLOUR = "0.35"  # dashed expected orbits / radii
EVENT_COLOURS = {"drop": "tab:red", "rejoin": "tab:green", "fault": "tab:purple", "kill": "tab:purple"}
DPI = 120


def size_for(n: int, small: float, large: float) -> float:
    """Interpolate a size from `small` (few agents) to `large` (~50 agents)."""
    f = min(1.0, max(0.0, (n - 6) / 44))
    return small + (large - small) * f


def agent_colours(run: RunData) -> list[Any]:
    """Leaders in shades of blue, followers in shades of yellow/orange."""
    leaders = run.leaders()
    followers = run.followers()
    colours: list[Any] = [None] * run.n_agents
    blues = plt.get_cmap("Blues")
    oranges = plt.get_cmap("YlOrBr")
    for rank, j in enumerate(leaders):
        colours[j] = blues(0.85 - 0.35 * (rank / max(1, len(leaders) - 1)))
    for rank, j in enumerate(followers):
        colours[j] = oranges(0.35 + 0.35 * (rank / max(1, len(followers) - 1)))
    return colours


def role_colour(leader: bool) -> Any:
    """The one colour a role stands for in legends."""
    return plt.get_cmap("Blues")(0.8) if leader else plt.get_cmap("YlOrBr")(0.5)


def role_handles(run: RunData, **style: Any) -> list[Line2D]:
    """Legend entries "leader" / "follower" for the roles present in the run, drawn with
    `style` (default: a line); the role colour goes in as `color` or, with a marker, `mfc`."""
    roles = {str(r) for r in run.role}
    style = style or {"lw": 1.5}
    key = "mfc" if "marker" in style else "color"
    return [Line2D([], [], **{key: role_colour(role == "leader")}, **style, label=role)
            for role in ("leader", "follower") if role in roles]


def role_legend(ax: Axes, run: RunData, extra: list[Line2D]) -> None:
    """The top-right legend of the line panels: the roles as lines, then `extra`."""
    ax.legend(handles=role_handles(run) + extra, fontsize=7, loc="upper right", framealpha=0.8)


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
