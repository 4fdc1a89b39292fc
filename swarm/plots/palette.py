"""How each agent looks, the same in every figure of a run (and in its animation): a
colour of its own from a qualitative colour map, a label ("L1" for leader 1, "4" for
follower 4), a line width (leaders twice as thick, every line thinner in a large swarm),
and the tree it belongs to (the leader its final out-neighbour path ends at) for the
legends and the small multiples that group agents by tree.

Colours: tab10 up to 9 agents, tab20 up to 18, then tab20 + tab20b + tab20c (54 colours),
cycled past that; greys are left out (grey means "not alive"), and the light half of each
map comes after the dark one, so neighbours in scenario order differ most.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.lines import Line2D

from swarm.contracts.orbits import root_of
from swarm.world.run_reader import RunData, final_graph

LEADER_MARKER = "*"
FOLLOWER_MARKER = "o"
NO_TREE = "no leader"


def _reordered(name: str, shades: int) -> list[Any]:
    """The colours of a qualitative map, darkest shade of every hue first, greys dropped."""
    cmap = plt.get_cmap(name)
    if not isinstance(cmap, ListedColormap):
        raise ValueError(f"{name}: not a qualitative (listed) colour map")
    cols = [tuple(float(v) for v in c) for c in np.asarray(cmap.colors)]  # RGB tuples, as the map lists them
    hues = len(cols) // shades
    out = [cols[h * shades + s] for s in range(shades) for h in range(hues)]
    return [c for c in out if not (abs(c[0] - c[1]) < 0.02 and abs(c[1] - c[2]) < 0.02)]


def palette(n: int) -> list[Any]:
    """`n` colours, as distinct as the qualitative maps allow (cycled past 54)."""
    if n <= 9:
        cols = _reordered("tab10", 1)
    elif n <= 18:
        cols = _reordered("tab20", 2)
    else:
        cols = _reordered("tab20", 2) + _reordered("tab20b", 4) + _reordered("tab20c", 4)
    return [cols[k % len(cols)] for k in range(n)]


@dataclass
class Tree:
    """One leader and the agents whose final path ends at it (`root` None: no leader)."""

    root: int | None
    columns: list[int]  # the leader's column first, then followers in scenario order

    @property
    def title(self) -> str:
        return NO_TREE if self.root is None else f"tree of L{self.root}"


@dataclass
class Looks:
    colours: list[Any]  # per column
    labels: list[str]  # per column: "L1" for a leader, "4" for a follower
    leader: list[bool]
    trees: list[Tree]
    lw: float  # a follower's line width

    def width(self, j: int) -> float:
        return self.lw * 2.0 if self.leader[j] else self.lw

    def handle(self, j: int, **style: Any) -> Line2D:
        """A legend entry for the agent of column `j` (a line, a star for leaders)."""
        kw: dict[str, Any] = dict(color=self.colours[j], lw=self.width(j), label=self.labels[j])
        if self.leader[j]:
            kw.update(marker=LEADER_MARKER, ms=9, mec="k", mew=0.5)
        kw.update(style)
        return Line2D([], [], **kw)


def line_width(n: int) -> float:
    """Thinner lines as the swarm grows: 1.2 for a few agents, 0.6 from about 40."""
    return max(0.6, 1.2 - 0.6 * max(0, n - 6) / 34)


def agent_trees(run: RunData) -> list[Tree]:
    """Agents grouped by the leader at the end of their last out-neighbour path (a dead
    agent's path uses its last alive choice); agents with no such path come last."""
    edges, _, _ = final_graph(run)
    leaders = {int(run.ids[j]) for j in run.leaders()}
    index = run.column_of()
    groups: dict[int | None, list[int]] = {int(run.ids[j]): [j] for j in run.leaders()}
    for j in run.followers():
        root, _ = root_of(int(run.ids[j]), edges, leaders)  # type: ignore[arg-type]
        groups.setdefault(root, []).append(j)
    trees = [Tree(r, cols) for r, cols in groups.items() if r is not None]
    trees.sort(key=lambda tr: index[tr.root])  # type: ignore[index]
    if None in groups:
        trees.append(Tree(None, groups[None]))
    return trees


def agent_looks(run: RunData) -> Looks:
    n = run.n_agents
    leader = [run.is_leader(j) for j in range(n)]
    labels = [("L" if leader[j] else "") + str(int(run.ids[j])) for j in range(n)]
    return Looks(palette(n), labels, leader, agent_trees(run), line_width(n))


def blank() -> Line2D:
    return Line2D([], [], ls="", label=" ")


def tree_legend_handles(looks: Looks, columns: list[int] | None = None) -> tuple[list[Line2D], int]:
    """Legend entries grouped by tree, one legend column per tree (headed by the tree's
    title, padded to equal length), and the number of columns to pass to `legend`."""
    keep = set(range(len(looks.colours)) if columns is None else columns)
    groups = [(tr.title, [j for j in tr.columns if j in keep]) for tr in looks.trees]
    groups = [g for g in groups if g[1]]
    if len(groups) > 6:  # too many trees for a column each: one flat list
        flat = [looks.handle(j) for _, cols in groups for j in cols]
        return flat, max(1, min(8, len(flat) // 10 + 1))
    rows = max(len(cols) for _, cols in groups) + 1
    handles: list[Line2D] = []
    for title, cols in groups:
        column = [Line2D([], [], ls="", label=title)] + [looks.handle(j) for j in cols]
        handles += column + [blank() for _ in range(rows - len(column))]
    return handles, len(groups)
