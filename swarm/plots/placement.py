"""Keeping labels and markers apart: line-end labels spread along one axis, point labels
placed greedily around their points, and markers that would sit on top of each other
stacked. Sizes are in points; an axes' size in points comes from the figure's layout.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from swarm.plots.style import figure_of


def axes_size_pt(ax: Axes) -> tuple[float, float]:
    """(width, height) of the axes in points once the figure's layout engine has run (run
    once per axes, at its first call: draw what takes room, legends too, before asking)."""
    cached = getattr(ax, "_swarm_size_pt", None)
    if cached is not None:
        return cached
    fig = figure_of(ax)
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
    pos = ax.get_position()
    w, h = fig.get_size_inches()
    size = (max(pos.width * w * 72, 1.0), max(pos.height * h * 72, 1.0))
    ax._swarm_size_pt = size  # type: ignore[attr-defined]
    return size


def spread_1d(values: Sequence[float], gap: float, lo: float = -math.inf, hi: float = math.inf) -> np.ndarray:
    """Positions as close to `values` as possible, in the same order, at least `gap` apart,
    within [lo, hi] when there is room (clusters of crowded labels centred on their values)."""
    v = np.asarray(values, dtype=float)
    out = np.empty_like(v)
    if v.size == 0:
        return out
    order = np.argsort(v, kind="stable")
    clusters: list[list[Any]] = []  # [start, members (indices into v)]

    def start_of(members: list[int]) -> float:
        s = float(np.mean([v[m] - k * gap for k, m in enumerate(members)]))
        top = hi - (len(members) - 1) * gap
        return min(max(s, lo), top) if top >= lo else lo

    for i in order:
        clusters.append([start_of([int(i)]), [int(i)]])
        while len(clusters) > 1 and clusters[-2][0] + len(clusters[-2][1]) * gap > clusters[-1][0]:
            last = clusters.pop()
            members = clusters[-1][1] + last[1]
            clusters[-1] = [start_of(members), members]
    for s, members in clusters:
        for k, m in enumerate(members):
            out[m] = s + k * gap
    return out


def stack_offsets(x: np.ndarray, y: np.ndarray, sep: float, step: float, levels: int = 6) -> np.ndarray:
    """For markers at (x, y) in points: (dx, dy) offsets (points) per marker, (K, 2), so
    that no two sit within `sep` of each other: the k-th marker of a crowd moves up by
    k * `step`; past `levels` a new column starts `sep` to the right."""
    off = np.zeros((len(x), 2))
    placed: list[tuple[float, float]] = []
    for i in np.lexsort((y, x)):
        k = 0
        while True:
            dx, dy = (k // levels) * sep, (k % levels) * step
            if not any(abs(x[i] + dx - px) < sep and abs(y[i] + dy - py) < sep for px, py in placed):
                break
            k += 1
        off[i] = (dx, dy)
        placed.append((float(x[i] + dx), float(y[i] + dy)))
    return off


def place_point_labels(
    ax: Axes, xy: np.ndarray, texts: list[str], fontsize: float, obstacles: np.ndarray | None = None
) -> list[tuple[float, float]]:
    """Offsets (points) for labels of the data points `xy` (K, 2), chosen greedily (in the
    given order) among positions round each point so that no label box overlaps another
    label or a point of `xy` / `obstacles`; far-off labels should get a leader line."""
    w_pt, h_pt = axes_size_pt(ax)
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    kx, ky = w_pt / max(x1 - x0, 1e-12), h_pt / max(y1 - y0, 1e-12)
    if ax.get_aspect() == 1.0:  # equal aspect: the tighter scale wins once the limits adjust
        kx = ky = min(kx, ky)
    pts = np.column_stack([xy[:, 0] * kx, xy[:, 1] * ky])
    obs = (
        pts
        if obstacles is None or not len(obstacles)
        else np.vstack([pts, np.column_stack([obstacles[:, 0] * kx, obstacles[:, 1] * ky])])
    )
    boxes: list[tuple[float, float, float, float]] = []
    r_mark = 4.0
    dirs = [(1, 1), (1, -1), (-1, 1), (-1, -1), (1, 0), (-1, 0), (0, 1), (0, -1)]
    result = []
    for i, text in enumerate(texts):
        w, h = 0.62 * fontsize * len(text) + 2, fontsize + 2
        best = None
        for dist in (5.0, 10.0, 16.0, 24.0, 34.0, 46.0):
            for dx, dy in dirs:
                ox, oy = dx * dist, dy * dist
                cx = pts[i, 0] + ox + (w / 2 if dx > 0 else -w / 2 if dx < 0 else 0)
                cy = pts[i, 1] + oy + (h / 2 if dy > 0 else -h / 2 if dy < 0 else 0)
                box = (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)
                if _free(box, boxes, obs, r_mark):
                    best = (ox, oy, box)
                    break
            if best is not None:
                break
        if best is None:
            ox, oy = 5.0, 5.0
            best = (ox, oy, (pts[i, 0] + ox, pts[i, 1] + oy, pts[i, 0] + ox + w, pts[i, 1] + oy + h))
        boxes.append(best[2])
        result.append((best[0], best[1]))
    return result


def _free(
    box: tuple[float, float, float, float], boxes: list[tuple[float, float, float, float]], points: np.ndarray, r: float
) -> bool:
    a0, b0, a1, b1 = box
    for c0, d0, c1, d1 in boxes:
        if a0 < c1 and c0 < a1 and b0 < d1 and d0 < b1:
            return False
    inside = (points[:, 0] > a0 - r) & (points[:, 0] < a1 + r) & (points[:, 1] > b0 - r) & (points[:, 1] < b1 + r)
    return not bool(inside.any())


def ha_va(ox: float, oy: float) -> tuple[str, str]:
    """Text alignment for a label offset by (ox, oy) from its point."""
    return (
        "left" if ox > 0 else "right" if ox < 0 else "center",
        "bottom" if oy > 0 else "top" if oy < 0 else "center",
    )
