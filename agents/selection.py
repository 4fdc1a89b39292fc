"""Out-neighbour selection from one sensor frame (paper, Definition 2).

Each follower picks the closest agent it senses; ties go to the lowest id (the paper
allows any). Leaders are sinks. With selection = "fixed" a follower keeps the agent
named by its `follow` while it senses it, and falls back to the nearest sensed agent
otherwise (and says so). Hysteresis h in [0, 1): keep the current out-neighbour unless
another is closer than (1 - h) times its range. Pure: no I/O.
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
           hysteresis: float = 0.0) -> Choice:
    """Choose a follower's out-neighbour among `contacts`."""
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
