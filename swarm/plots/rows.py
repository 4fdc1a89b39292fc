"""The frame of a panel with a row per follower over time (neighbours.png, states.png): the
rows' labels in the followers' colours, time along x, and a column of figures at the right."""

from __future__ import annotations

from matplotlib.axes import Axes

from swarm.plots.context import Ctx


def follower_rows(ax: Axes, ctx: Ctx, followers: list[int], t0: float, t_end: float, fs: float, title: str) -> None:
    """The frame of a panel with a row per follower over time (neighbours.png, states.png): each
    row's label on a patch of the follower's colour, time along x, the title."""
    looks = ctx.looks
    ax.set_yticks(range(len(followers)), [looks.labels[j] for j in followers], fontsize=fs)
    for tick, j in zip(ax.get_yticklabels(), followers):
        tick.set_bbox(dict(boxstyle="round,pad=0.15", fc=looks.colours[j], ec="none", alpha=0.55))
    ax.set_ylim(max(len(followers), 1) - 0.5, -0.5)
    ax.set_xlim(t0, t_end)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("follower")
    ax.set_title(title)
    ax.grid(True, axis="x", lw=0.3, alpha=0.5)


def margin_column(ax: Axes, heading: str, values: list[str], fs: float) -> None:
    """A column of small grey figures right of a panel's rows (row k: values[k]), headed `heading`."""
    ax.annotate(
        heading,
        (1.0, 1.0),
        xycoords="axes fraction",
        xytext=(3, 2),
        textcoords="offset points",
        va="bottom",
        fontsize=fs,
        color="0.3",
    )
    for row, text in enumerate(values):
        ax.annotate(
            text,
            (1.0, row),
            xycoords=("axes fraction", "data"),
            xytext=(3, 0),
            textcoords="offset points",
            va="center",
            fontsize=fs,
            color="0.3",
        )
