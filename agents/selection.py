"""Out-neighbour selection from one sensor frame (paper, Definition 2).

Each follower picks the closest agent it senses; ties go to the lowest id (the paper
allows any). Leaders are sinks. With selection = "fixed" a follower keeps the agent
named by its `follow` while it senses it, and falls back to the nearest sensed agent
otherwise (and says so). With selection = "rooted" only agents that advertise a path to
a leader (hops >= 0) are candidates, which keeps the paper's Assumption 1 true wherever
a rooted agent is in sight: nearest choice alone can pair two followers in a cycle.
Hysteresis h in [0, 1): keep the current out-neighbour unless another is closer than
(1 - h) times its range. Neither rule bounds the number of switches: as agents move,
the nearest (rooted) agent keeps changing, and a follower that alternates between two
leaders' trees never settles.

selection = "sticky" (the default, `Sticky` in agents/sticky.py) makes the paper's nearest choice once,
waits for it to be rooted, and keeps it until it is lost (holding it through a short
loss of its path, coasting on it through a short spell out of sight), and with nothing
rooted in reach shadows an agent it senses or searches: loop-free, at most 4 changes
per loss. This module holds the per-tick rules (select, nearest, keeps_current, keeps_out,
feasible_kept, advertised) that it and the batch use. Pure: no I/O.
"""

from __future__ import annotations

import math
from operator import attrgetter
from typing import Any, NamedTuple

from swarm.agents.ops import SCALAR, Num, Ops
from swarm.contracts.fastpath import compiled as _c
from swarm.contracts.frames import Contact


def reach(sensing_range: float | None, fraction: float) -> float:
    """The range (m) within which a sticky follower makes new choices: `fraction`
    (SelectionTuning.reach) x its sensing range (inf when unlimited). Kept choices last while
    sensed at all, so an agent near the edge of the range, in and out of sight, is not taken
    and lost tick after tick."""
    return math.inf if sensing_range is None else fraction * sensing_range


def cone(fov: float | None, fraction: float) -> float | None:
    """The same for a field of view: new choices within `fraction` x half of it from the heading."""
    return None if fov is None or fov >= 2 * math.pi else fraction * 0.5 * fov


class Choice(NamedTuple):
    out: int | None  # chosen out-neighbour id, None if nobody is sensed (or a leader)
    contact: Contact | None
    fallback: bool  # a pinned out-neighbour was not sensed and the nearest was used instead
    rooted: bool = True  # sticky rule: advertise a path through `out` (False while acquiring)


_RANGE_ID = attrgetter("range", "id")


def nearest_py(contacts: tuple[Contact, ...]) -> Contact | None:
    """The contact with the smallest (range, id), the first of equals; None if there is none.
    min() in C: half the time of a Python loop over 99 contacts. The reference of `nearest`."""
    return min(contacts, key=_RANGE_ID, default=None)


def _nearest_c(contacts: tuple[Contact, ...]) -> Contact | None:
    """nearest_py in the compiled module (swarm/contracts/fastpath.py), which leaves what is not
    a tuple of tuples with a float range and an int id to nearest_py."""
    assert _c is not None
    best = _c.nearest(contacts)
    return nearest_py(contacts) if best is NotImplemented else best


# The contact with the smallest (range, id), the first of equals; None if there is none.
nearest = nearest_py if _c is None else _nearest_c


def keeps_current(r_best: Num, r_current: Num, hysteresis: Num) -> Num:
    """Hysteresis h: the current out-neighbour (range r_current) stays unless the nearest
    candidate (r_best) is closer than (1 - h) times its range. On floats, or on arrays of
    followers (agents/batch_select.py): the same test."""
    return r_best > (1.0 - hysteresis) * r_current


def keeps_out(sensed: Any, hops_out: Num) -> Any:
    """The "rooted" condition of a committed follower (KEEP, HOLD or COAST to KEEP;
    docs/design/selection.md#states): its out-neighbour is sensed and advertises a path.
    On one follower (a bool and an int: Sticky's handlers) or on arrays of followers
    (agents/batch_sticky.py's keep): the same test."""
    return sensed & (hops_out >= 0)


def feasible_kept(feasible: Num, hops_out: Num, ops: Ops = SCALAR) -> Num:
    """A follower's feasible count after that transition: no more than its out-neighbour's
    hops + 1 (`SCALAR`: Sticky._rooted; `batch_maths.ARRAY`: the batch's keep)."""
    return ops.minimum(feasible, hops_out + 1)


def advertised(hops_out: Num, rooted: Any, max_hops: int, none: Any, ops: Ops = SCALAR) -> Num:
    """The hop count a follower advertises through its out-neighbour (advertising hops_out):
    hops_out + 1 where it is rooted (Choice.rooted) with 0 <= hops_out < max_hops, else `none`.
    On one follower or on arrays of followers (agents/batch.py)."""
    return ops.where(rooted & (hops_out >= 0) & (hops_out < max_hops), hops_out + 1, none)


def select(
    contacts: tuple[Contact, ...],
    *,
    mode: str,
    pinned: int | None,
    current: int | None,
    hysteresis: float = 0.0,
    below: int | None = None,
) -> Choice:
    """Choose a follower's out-neighbour among `contacts`.

    rooted mode: candidates advertise hops >= 0 and, when `below` is given, hops < below
    (the current out-neighbour stays a candidate while it is rooted). A follower's
    descendants advertise more hops than it does, so with below = its own hop count it
    can never pick one: switching is loop-free (the feasibility condition of
    distance-vector routing).
    """
    if mode == "rooted":
        contacts = tuple(c for c in contacts if c.hops >= 0 and (below is None or c.hops < below or c.id == current))
    if mode == "fixed" and pinned is not None:
        for c in contacts:
            if c.id == pinned:
                return Choice(c.id, c, False)
        fallback = True
    else:
        fallback = False
    best = nearest(contacts)
    if best is None:
        return Choice(None, None, fallback)
    if hysteresis > 0.0 and current is not None and current != best.id:
        for c in contacts:
            if c.id == current and keeps_current(best.range, c.range, hysteresis):
                return Choice(c.id, c, fallback)
    return Choice(best.id, best, fallback)
