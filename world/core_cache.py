"""What WorldCore keeps between ticks so as not to make it again each tick: the agents'
states as a list that counts its changes (`_States`), who is where derived from one version
of them (`_Roster`), and one tick's sensing, each form made when first asked for (`_Sensed`).
Also the states as module names (ACTIVE, COASTING, GONE; world/core.py re-exports them).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm.contracts.vocabulary import AgentState

# The states as module names (world/, tests/pure/test_sim.py import them)
ACTIVE, COASTING, GONE = AgentState.ACTIVE, AgentState.COASTING, AgentState.GONE


class _Sensed:
    """One tick's sensing, each form made when first asked for (`WorldCore.sensing`,
    `WorldCore.sensed_pairs`); the core forgets it when poses or presence change."""

    __slots__ = ("matrices", "pairs")

    def __init__(self) -> None:
        self.matrices: tuple | None = None
        self.pairs: tuple | None = None


class _States(list):
    """`WorldCore.state`: a list of the agents' states that counts its changes (`version`), so
    that what the core derives from it each tick (`WorldCore._roster`) is made again only
    after one, however the list is changed (every mutating method of list bumps it)."""

    __slots__ = ("version",)

    def __init__(self, items: Any = ()) -> None:
        super().__init__(items)
        self.version = 0


def _bumping(name: str) -> Any:
    base = getattr(list, name)

    def changed(self: _States, *args: Any, **kwargs: Any) -> Any:
        try:
            return base(self, *args, **kwargs)
        finally:  # after the change: a roster built meanwhile is of the old version, and stale
            self.version += 1

    changed.__name__ = changed.__qualname__ = name
    return changed


for _name in (
    "__setitem__",
    "__delitem__",
    "__iadd__",
    "__imul__",
    "append",
    "extend",
    "insert",
    "pop",
    "remove",
    "clear",
    "sort",
    "reverse",
):
    setattr(_States, _name, _bumping(_name))


class _Roster:
    """Who is where, derived from one version of the states (`WorldCore._roster`): the active
    agents' ids, the alive and present masks, the coasting and the gone agents' indices."""

    __slots__ = ("states", "version", "active_ids", "alive", "present", "coasting", "gone")

    def __init__(self, states: _States, ids: np.ndarray):
        self.states, self.version = states, states.version
        ids_l = ids.tolist()
        self.active_ids = [ids_l[k] for k, s in enumerate(states) if s == ACTIVE]
        self.alive = np.array([s == ACTIVE for s in states], dtype=bool)
        self.present = np.array([s != GONE for s in states], dtype=bool)
        self.coasting = [k for k, s in enumerate(states) if s == COASTING]
        self.gone = [k for k, s in enumerate(states) if s == GONE]
