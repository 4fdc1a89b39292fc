"""`render_animation`: the run as a GIF (``animation.gif``, matplotlib's PillowWriter; no
ffmpeg needed): every agent in its colour (palette.py; leaders as stars, labelled up to
`GROUP_ABOVE` agents) with a trail of its last few seconds, an edge from each live
follower to its out-neighbour (in the follower's colour), a red ring where an
out-neighbour switch just happened, grey agents while not alive, the target and the
expected orbits, the time and the switch count so far.

At most `MAX_FRAMES` frames, evenly spaced over the run (a 300 s run: one frame per
1.5 s of simulated time). The figure is drawn once; each frame only redraws its own
artists on that background (blitting) before the writer takes it, so a long run animates
in seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle
from matplotlib.transforms import offset_copy
from PIL import Image

from swarm.plots.context import GROUP_ABOVE, Ctx, make_context
from swarm.plots.palette import LEADER_MARKER
from swarm.plots.style import DEAD_COLOUR, EXPECTED_COLOUR, TARGET_COLOUR, figure_of, size_for
from swarm.world.metrics import switch_ticks
from swarm.world.run_reader import expected_radii, load_run

ANIMATION_FILE = "animation.gif"
MAX_FRAMES = 200
FPS = 12
TRAIL_S = 8.0  # trail length (s), at most TRAIL_FRACTION of the run
TRAIL_FRACTION = 0.25
TRAIL_POINTS = 60  # points per trail
SWITCH_HOLD = 3  # frames a switch ring stays
SIZE_IN, DPI = 6.4, 85


def frame_rows(n_rows: int, max_frames: int) -> np.ndarray:
    return np.unique(np.linspace(0, n_rows - 1, max(1, min(max_frames, n_rows))).round().astype(np.int64))


def _limits(ctx: Ctx) -> tuple[float, float, float, float]:
    run = ctx.run
    tx, ty = run.target
    xs, ys = run.x[np.isfinite(run.x)], run.y[np.isfinite(run.y)]
    r = max(expected_radii(run) or [1.0])
    x0, x1 = min(float(xs.min(initial=tx)), tx - r), max(float(xs.max(initial=tx)), tx + r)
    y0, y1 = min(float(ys.min(initial=ty)), ty - r), max(float(ys.max(initial=ty)), ty + r)
    pad = 0.05 * max(x1 - x0, y1 - y0)
    return x0 - pad, x1 + pad, y0 - pad, y1 + pad


class _Frames:
    """The artists of the animation and how frame k (a row of the run) updates them."""

    def __init__(self, ax: plt.Axes, ctx: Ctx, rows: np.ndarray) -> None:
        run, looks = ctx.run, ctx.looks
        self.ctx, self.rows, self.ax = ctx, rows, ax
        dt = float(run.t[1] - run.t[0]) if run.n_rows > 1 else 1.0
        span = float(run.t[-1] - run.t[0])
        self.trail = max(1, int(round(min(TRAIL_S, TRAIL_FRACTION * span) / dt)))
        self.index = run.column_of()
        ticks = switch_ticks(run.out, run.alive)
        self.switch_at = [set(int(k) for k in ks) for ks in ticks]
        self.switch_cum = np.cumsum(
            np.bincount(np.concatenate(ticks + [np.zeros(0, np.int64)]).astype(np.int64), minlength=run.n_rows)
        )
        self.trails = [
            ax.plot([], [], color=looks.colours[j], lw=looks.width(j), alpha=0.75, zorder=2)[0]
            for j in range(run.n_agents)
        ]
        self.edges = LineCollection([], lw=0.9, alpha=0.8, zorder=1.5)
        ax.add_collection(self.edges)
        lead = [j for j in range(run.n_agents) if looks.leader[j]]
        foll = [j for j in range(run.n_agents) if not looks.leader[j]]
        self.groups = [
            (foll, ax.scatter([], [], s=40, marker="o", edgecolors="k", linewidths=0.5, zorder=4)),
            (lead, ax.scatter([], [], s=170, marker=LEADER_MARKER, edgecolors="k", linewidths=0.6, zorder=4.5)),
        ]
        self.rings = ax.scatter(
            [], [], s=size_for(run.n_agents, 260, 140), facecolors="none", edgecolors="red", linewidths=1.8, zorder=5
        )
        fs = size_for(run.n_agents, 8, 6)
        beside = offset_copy(ax.transData, fig=figure_of(ax), x=6, y=4, units="points")
        self.labels = (
            [
                ax.text(
                    0,
                    0,
                    looks.labels[j],
                    fontsize=fs,
                    zorder=6,
                    clip_on=True,
                    transform=beside,
                    fontweight="bold" if looks.leader[j] else "normal",
                )
                for j in range(run.n_agents)
            ]
            if run.n_agents <= GROUP_ABOVE
            else []
        )
        self.clock = ax.text(
            0.02,
            0.98,
            "",
            transform=ax.transAxes,
            va="top",
            fontsize=9,
            bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.6", alpha=0.9),
            zorder=7,
        )
        self.artists = [self.edges, *self.trails, *(sc for _, sc in self.groups), self.rings, *self.labels, self.clock]
        for a in self.artists:
            a.set_animated(True)  # drawn by frame, not with the background

    def __call__(self, f: int) -> list:
        run, looks, k = self.ctx.run, self.ctx.looks, int(self.rows[f])
        lo = max(0, k - self.trail)
        step = max(1, (k - lo) // TRAIL_POINTS)
        alive = run.alive[k]
        for j, line in enumerate(self.trails):
            idx = np.r_[lo:k:step, k]
            line.set_data(
                np.where(run.alive[idx, j], run.x[idx, j], np.nan), np.where(run.alive[idx, j], run.y[idx, j], np.nan)
            )
        segs, cols = [], []
        for j in range(run.n_agents):
            o = int(run.out[k, j])
            if alive[j] and o in self.index and alive[self.index[o]] and not looks.leader[j]:
                segs.append([(run.x[k, j], run.y[k, j]), (run.x[k, self.index[o]], run.y[k, self.index[o]])])
                cols.append(looks.colours[j])
        self.edges.set_segments(segs)
        self.edges.set_colors(cols)
        for cols_, sc in self.groups:
            sc.set_offsets(np.column_stack([run.x[k, cols_], run.y[k, cols_]]) if cols_ else np.zeros((0, 2)))
            sc.set_facecolor([looks.colours[j] if alive[j] else DEAD_COLOUR for j in cols_])
        prev = int(self.rows[max(0, f - SWITCH_HOLD)]) if f else -1
        ring = [j for j in range(run.n_agents) if any(prev < s <= k for s in self.switch_at[j])]
        self.rings.set_offsets(np.column_stack([run.x[k, ring], run.y[k, ring]]) if ring else np.zeros((0, 2)))
        for j, text in enumerate(self.labels):
            text.set_position((run.x[k, j], run.y[k, j]))
            text.set_text(looks.labels[j] if np.isfinite(run.x[k, j]) else "")
        gone = int((~alive).sum())
        self.clock.set_text(
            f"t = {run.t[k]:6.1f} s   switches: {int(self.switch_cum[k])}" + (f"   not alive: {gone}" if gone else "")
        )
        return self.artists


def render_animation(
    run_dir: Path, max_frames: int = MAX_FRAMES, fps: int = FPS, progress: Callable[[int, int], None] | None = None
) -> Path:
    """Write ``animation.gif`` into `run_dir` (at most `max_frames` frames at `fps`);
    `progress(frame, total)` is called as frames are written. Returns the path."""
    run_dir = Path(run_dir)
    ctx = make_context(load_run(run_dir))
    run = ctx.run
    rows = frame_rows(run.n_rows, max_frames)
    x0, x1, y0, y1 = _limits(ctx)
    ratio = min(max((y1 - y0) / (x1 - x0), 0.5), 1.5)  # the figure in the paths' shape
    fig, ax = plt.subplots(figsize=(SIZE_IN, SIZE_IN * ratio + 0.9), layout="constrained")
    tx, ty = run.target
    for r in expected_radii(run):
        ax.add_patch(Circle((tx, ty), r, fill=False, ls="--", lw=0.8, ec=EXPECTED_COLOUR, zorder=1))
    ax.plot(tx, ty, marker="*", ms=13, color=TARGET_COLOUR, mec="k", mew=0.6, zorder=3)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.3, alpha=0.5)
    name = run.summary.get("scenario")
    ax.set_title(f"{name + ': ' if name else ''}{run.n_agents} agents, {float(run.t[-1]):.0f} s")
    fig.legend(
        handles=[
            Line2D([], [], ls="", marker=LEADER_MARKER, ms=11, mfc="0.7", mec="k", label="leader"),
            Line2D([], [], color="0.4", lw=1.0, label="follower → out-neighbour"),
            Line2D([], [], ls="", marker="o", ms=10, mfc="none", mec="red", mew=1.8, label="switch"),
            Line2D([], [], ls="", marker="o", ms=6, mfc=DEAD_COLOUR, mec="k", label="not alive"),
        ],
        loc="outside lower center",
        ncol=4,
        fontsize=7,
    )
    frames = _Frames(ax, ctx, rows)
    fig.set_dpi(DPI)
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)  # lay out once, not at every frame
    fig.set_layout_engine("none")
    path = run_dir / ANIMATION_FILE
    tmp = path.with_name(f".{path.name}.tmp.gif")
    writer = _BlitWriter(fps=max(1, int(fps)))
    try:
        with writer.saving(fig, tmp, DPI):
            canvas = agg_canvas(fig)
            canvas.draw()  # everything but the frame's own artists (animated: left out)
            background = canvas.copy_from_bbox(fig.bbox)
            for f in range(len(rows)):
                canvas.restore_region(background)
                for artist in frames(f):
                    ax.draw_artist(artist)
                writer.grab_frame()
                if progress is not None:
                    progress(f + 1, len(rows))
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)
    return path


def agg_canvas(fig: Figure) -> FigureCanvasAgg:
    """The figure's canvas, an Agg one (swarm/plots/__init__.py selects the Agg backend)."""
    canvas = fig.canvas
    if not isinstance(canvas, FigureCanvasAgg):
        raise TypeError(f"the animation draws on an Agg canvas, not {type(canvas).__name__}")
    return canvas


class _BlitWriter(PillowWriter):
    """PillowWriter taking each frame from the canvas as drawn (background restored, the
    frame's artists drawn on it) instead of redrawing the whole figure."""

    def grab_frame(self, **savefig_kwargs) -> None:
        canvas = agg_canvas(self.fig)
        w, h = canvas.get_width_height(physical=True)
        image = Image.frombuffer("RGBA", (w, h), bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1)
        self._frames.append(image.convert("RGB"))  # type: ignore[attr-defined]  # PillowWriter's list, not in its stubs


def gif_frames(path: Path) -> int:
    """Number of frames in a GIF (for the tests and the CLI's report)."""
    with Image.open(path) as im:
        return int(getattr(im, "n_frames", 1))
