"""Out-neighbour selection from one sensor frame (paper, Definition 2).

Each follower picks the closest agent it senses; ties go to the lowest id (the paper
allows any). Leaders are sinks. With selection = "fixed" a follower keeps the agent
named by its `follow` while it senses it, and falls back to the nearest sensed agent
otherwise (and says so). With selection = "rooted" only agents that advertise a path to
a leader (hops >= 0) are candidates, which keeps the paper's Assumption 1 true wherever
a rooted agent is in sight: nearest choice alone can pair two followers in a cycle.
Hysteresis h in [0, 1): keep the current out-neighbour unless another is closer than
(1 - h) times its range. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

from world.frames import Contact


@dataclass(frozen=True, slots=True)
class Choice:
    out: int | None  # chosen out-neighbour id, None if nobody is sensed (or a leader)
    contact: Contact | None
    fallback: bool  # a pinned out-neighbour was not sensed and the nearest was used instead


def nearest(contacts: tuple[Contact, ...]) -> Contact | None:
    best = None
    for c in contacts:
        if best is None or (c.range, c.id) < (best.range, best.id):
            best = c
    return best


def select(contacts: tuple[Contact, ...], *, mode: str, pinned: int | None, current: int | None,
           hysteresis: float = 0.0, below: int | None = None) -> Choice:
    """Choose a follower's out-neighbour among `contacts`.

    rooted mode: candidates advertise hops >= 0 and, when `below` is given, hops < below
    (the current out-neighbour stays a candidate while it is rooted). A follower's
    descendants advertise more hops than it does, so with below = its own hop count it
    can never pick one: switching is loop-free (the feasibility condition of
    distance-vector routing).
    """
    if mode == "rooted":
        contacts = tuple(c for c in contacts if c.hops >= 0 and (below is None or c.hops < below
                                                                 or c.id == current))
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
            if c.id == current and best.range > (1.0 - hysteresis) * c.range:
                return Choice(c.id, c, fallback)
    return Choice(best.id, best, fallback)
