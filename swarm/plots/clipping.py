"""The y-range of the control panel: set by the followers, not by the leaders' start.

A leader's circle-circle path starts at its turn-rate limit (up to 10 rad/s for a few
tenths of a second) while the followers turn at about 1 rad/s: drawn to scale, the
followers' inputs are a flat line. `control_range` takes the range from the followers'
inputs over the whole run (their law bounds them, so their transients stay in view) and
every agent's inputs after the first seconds (robust percentiles: the leaders' orbit hold,
not a lone glitch), padded; what lies well beyond it is clipped and `mark_clips` marks each clipped excursion with a
triangle on the panel's edge, the largest named ("clipped: 10 rad/s at t=0 (L6)").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.transforms import Transform, offset_copy

from swarm.plots.palette import Looks
from swarm.plots.placement import axes_size_pt, stack_offsets
from swarm.plots.style import figure_of
from swarm.world.run_reader import RunData

START_S = 5.0  # "the first seconds": this long, or the first START_FRACTION of a short run
START_FRACTION = 0.5
PERCENTILE = 0.5  # robust range: [0.5 %, 99.5 %] of the samples that set it
PAD = 0.08  # padding, as a fraction of the range
CLIP_BEYOND = 0.25  # clip only what lies more than this fraction of the range outside it
MAX_MARKS = 40  # clip markers drawn (the largest excursions)
NOTE_FONT = 7.0
NOTE_RISE = 5.0  # pt: the top note's bottom, above the axes


@dataclass
class Clip:
    column: int
    t: float  # s, when the excursion starts
    value: float  # rad/s, the peak


@dataclass
class ControlRange:
    lo: float
    hi: float
    clipped: list[Clip] = field(default_factory=list)


def _robust(values: np.ndarray) -> tuple[float, float] | None:
    v = values[np.isfinite(values)]
    if not v.size:
        return None
    lo, hi = np.percentile(v, [PERCENTILE, 100 - PERCENTILE])
    return float(lo), float(hi)


def _extent(values: np.ndarray) -> tuple[float, float] | None:
    v = values[np.isfinite(values)]
    return (float(v.min()), float(v.max())) if v.size else None


def control_range(run: RunData) -> ControlRange:
    """The followers' whole range (their law bounds it: their transients stay in view)
    joined with the robust range of every agent after the first seconds, padded; a
    leader-only run: the robust range after the first seconds."""
    u = np.where(run.alive, run.u, np.nan)
    full = _extent(u)
    if full is None:
        return ControlRange(-1.0, 1.0)
    t0, t1 = float(run.t[0]), float(run.t[-1])
    later = run.t >= t0 + min(START_S, START_FRACTION * (t1 - t0))
    parts = [p for p in (_robust(u[later]), _extent(u[:, run.followers()])) if p is not None]
    lo = min([p[0] for p in parts] + [0.0])  # u = 0 (going straight) stays in view
    hi = max([p[1] for p in parts] + [0.0])
    span = max(hi - lo, 0.2)
    lo, hi = lo - PAD * span, hi + PAD * span
    lo = full[0] - PAD * span if full[0] >= lo - CLIP_BEYOND * span else lo
    hi = full[1] + PAD * span if full[1] <= hi + CLIP_BEYOND * span else hi
    if full[0] >= lo and full[1] <= hi:
        return ControlRange(lo, hi)
    return ControlRange(lo, hi, _excursions(run, u, lo, hi))


def _excursions(run: RunData, u: np.ndarray, lo: float, hi: float) -> list[Clip]:
    """Every stretch of samples outside [lo, hi] (its start, its peak), largest first (MAX_MARKS)."""
    clips = []
    for j in range(run.n_agents):
        col = u[:, j]
        for side in (col > hi, col < lo):
            if not side.any():
                continue
            edges = np.diff(np.concatenate([[0], side.astype(np.int8), [0]]))
            for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
                k = a + int(np.argmax(np.abs(col[a:b])))
                clips.append(Clip(j, float(run.t[a]), float(col[k])))
    clips.sort(key=lambda c: -abs(c.value))
    return clips[:MAX_MARKS]


def _fmt_t(t: float) -> str:
    return "0" if abs(t) < 5e-3 else f"{t:.2f} s"


def clip_text(clips: list[Clip], looks: Looks) -> str:
    """'clipped: 10 rad/s at t=0 (L6)'; more names and '+k more' when several agents are."""
    first = clips[0]
    text = f"clipped: {first.value:.3g} rad/s at t={_fmt_t(first.t)} ({looks.labels[first.column]})"
    others = sorted({looks.labels[c.column] for c in clips[1:]} - {looks.labels[first.column]})
    if others:
        text += "; also " + ", ".join(others[:4]) + (f" +{len(others) - 4}" if len(others) > 4 else "")
    return text


def mark_clips(ax: Axes, rng: ControlRange, looks: Looks, columns: list[int]) -> None:
    """Triangles on the top/bottom edge where the agents of `columns` go beyond the range
    (stacked where they would overlap), the largest excursion of each side named in a note."""
    mine = [c for c in rng.clipped if c.column in set(columns)]
    if not mine:
        return
    w_pt, _ = axes_size_pt(ax)
    x0, x1 = ax.get_xlim()
    kx = w_pt / max(x1 - x0, 1e-12)
    for top in (True, False):
        side = [c for c in mine if (c.value > rng.hi) == top]
        if not side:
            continue
        xs = np.array([c.t * kx for c in side])
        off = stack_offsets(xs, np.zeros(len(side)), sep=6.0, step=7.0)
        sign = -1.0 if top else 1.0  # stack into the axes
        for c, (dx, dy) in zip(side, off):
            ax.plot(
                [c.t],
                [rng.hi if top else rng.lo],
                ls="",
                marker="^" if top else "v",
                ms=7,
                mfc=looks.colours[c.column],
                mec="k",
                mew=0.6,
                clip_on=False,
                zorder=6,
                transform=_offset(ax, dx, sign * (dy + 3.5)),
            )
        _name(ax, clip_text(side, looks), side[0], rng.hi if top else rng.lo, top)


def _name(ax: Axes, text: str, big: Clip, edge: float, top: bool) -> None:
    """The note next to the largest excursion's marker, pointing at it: just above the axes
    for the top edge (clear of the data and of the event labels hanging from the top),
    just inside for the bottom one; on the marker's right in the first half of the run."""
    x0, x1 = ax.get_xlim()
    right = (big.t - x0) / max(x1 - x0, 1e-12) < 0.5
    ax.annotate(
        text,
        (big.t, edge),
        xytext=(16.0 if right else -16.0, NOTE_RISE if top else 10.0),
        textcoords="offset points",
        ha="left" if right else "right",
        va="bottom",
        fontsize=NOTE_FONT,
        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="0.5", lw=0.6, alpha=0.9),
        annotation_clip=False,
        arrowprops=dict(arrowstyle="->", color="0.3", lw=0.7, shrinkB=7),
        zorder=7,
    )
    if top:  # the title goes up, above the note (which otherwise covers it)
        ax.set_title(ax.get_title(), pad=title_pad_over_note())


def title_pad_over_note() -> float:
    """A title's pad (pt) that keeps it above a note over the axes' top edge."""
    return NOTE_RISE + NOTE_FONT * 1.8 + float(plt.rcParams["axes.titlepad"])


def top_note(rng: ControlRange) -> bool:
    """Whether the control panel of every agent has a note over its top edge."""
    return any(c.value > rng.hi for c in rng.clipped)


def _offset(ax: Axes, dx_pt: float, dy_pt: float) -> Transform:
    return offset_copy(ax.transData, fig=figure_of(ax), x=dx_pt, y=dy_pt, units="points")
