"""states.png: each follower's follow state over time (trajectory.npz's `follow`): one row per
follower, a bar per stretch of one state in that state's colour (`STATE_COLOURS`), a legend
of the states the run has, and the share of the run each follower spent keeping its
out-neighbour. A run without the array (recorded before the follow states) has no states.png."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Patch

from swarm.contracts.vocabulary import FollowState
from swarm.contracts.wire import FOLLOW_STATES
from swarm.plots.context import Ctx
from swarm.plots.rows import follower_rows, margin_column
from swarm.plots.style import DEAD_COLOUR, size_for

#: One colour per follow state, the same in every run: committed in green, the ways of
#: steering without a path in warm colours, nobody to steer by in red / dark grey.
STATE_COLOURS: dict[str, str] = {
    FollowState.NONE: "0.88",
    FollowState.ACQUIRE: "#9ecae1",
    FollowState.KEEP: "#31a354",
    FollowState.HOLD: "#fdd835",
    FollowState.COAST: "#fb8c00",
    FollowState.SHADOW: "#8e63b5",
    FollowState.SEARCH: "#d7301f",
    FollowState.LOST: "#424242",
    FollowState.LATE: "#80cbc4",
}

#: What each state means, in the legend.
STATE_WORDS: dict[str, str] = {
    FollowState.NONE: "none (other rules)",
    FollowState.ACQUIRE: "acquire",
    FollowState.KEEP: "keep",
    FollowState.HOLD: "hold (out-neighbour lost its path)",
    FollowState.COAST: "coast (on a prediction)",
    FollowState.SHADOW: "shadow",
    FollowState.SEARCH: "search",
    FollowState.LOST: "lost",
    FollowState.LATE: "late (joined under way)",
}

DEAD = -1  # code of a stretch the follower was not alive


def has_states(ctx: Ctx) -> bool:
    """Whether the run recorded follow states (trajectory.npz has `follow`)."""
    return ctx.run.follow is not None


def stretches(codes: np.ndarray) -> list[tuple[int, int, int]]:
    """(first row, end row, code) of each run of equal codes in `codes` (1-D)."""
    if codes.size == 0:
        return []
    starts = np.concatenate([[0], np.flatnonzero(codes[1:] != codes[:-1]) + 1])
    ends = np.concatenate([starts[1:], [codes.size]])
    return [(int(a), int(b), int(codes[a])) for a, b in zip(starts, ends)]


def panel_states(ax: Axes, ctx: Ctx) -> None:
    """One row per follower: its follow state over time; grey hatched: not alive."""
    run = ctx.run
    assert run.follow is not None
    followers = run.followers()
    t = run.t
    dt = float(t[1] - t[0]) if run.n_rows > 1 else 1.0
    t_end = float(t[-1]) + dt
    fs = size_for(run.n_agents, 7, 5)
    seen: set[int] = set()
    keep = FOLLOW_STATES.index(FollowState.KEEP)
    shares: list[str] = []
    for row, j in enumerate(followers):
        codes = np.where(run.alive[:, j], run.follow[:, j].astype(np.int64), DEAD)
        by_code: dict[int, list[tuple[float, float]]] = {}
        for a, b, code in stretches(codes):
            x0 = float(t[a])
            x1 = float(t[b]) if b < run.n_rows else t_end
            by_code.setdefault(code, []).append((x0, x1 - x0))
        for code, spans in by_code.items():
            if code == DEAD:
                kw: dict[str, Any] = dict(facecolors="white", edgecolor=DEAD_COLOUR, hatch="////", lw=0.0)
            elif 0 <= code < len(FOLLOW_STATES):
                seen.add(code)
                kw = dict(facecolors=STATE_COLOURS[FOLLOW_STATES[code]], lw=0.0)
            else:  # a code this build does not know
                kw = dict(facecolors="magenta", lw=0.0)
            ax.broken_barh(spans, (row - 0.35, 0.7), **kw)
        alive = run.alive[:-1, j] if run.n_rows > 1 else run.alive[:, j]
        share = float((run.follow[: alive.size, j][alive] == keep).mean()) if alive.any() else 0.0
        shares.append(f"{100 * share:.0f}%")
    margin_column(ax, "keep", shares, fs)
    follower_rows(ax, ctx, followers, float(t[0]), t_end, fs, "follow state of each follower over time")
    handles = [
        Patch(facecolor=STATE_COLOURS[FOLLOW_STATES[c]], edgecolor="0.3", lw=0.3, label=STATE_WORDS[FOLLOW_STATES[c]])
        for c in sorted(seen)
    ]
    handles.append(Patch(facecolor="white", edgecolor=DEAD_COLOUR, hatch="////", label="not alive"))
    ax.figure.legend(handles=handles, fontsize=7, loc="outside lower center", ncol=min(len(handles), 5))
