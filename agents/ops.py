"""The elementary operations the shared laws are written in, and their scalar set.

The follower law (swarm.agents.laws.bearing_law, loiter_rate), the leaders' orbit hold and
CC arcs (swarm.agents.leader.orbit_hold, arc_rate) and the hysteresis of the selection
rules (swarm.agents.selection.keeps_current) are written once, over an `Ops`:

- `SCALAR` (here: the standard library on Python floats): what AgentBrain runs, in every
  agent process and in `swarm sim`;
- swarm.agents.batch_maths.ARRAY (numpy on (B, N) arrays): what the batch brains run
  (agents/batch.py).

The two sets compute every element with functions that round alike (batch_maths says
which call `math` per element to be sure), and the shared code applies them in one order,
so a batch run equals the per-agent run to the bit (tests/pure/test_batch.py,
tests/pure/test_batch_decisions.py). Standard library only: an agent process imports this
and no numpy. Pure: no I/O, no state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from swarm.contracts.orbits import wrap

if TYPE_CHECKING:  # numpy for the checker only: an agent process does not import it
    import numpy as np

    Num = TypeVar("Num", float, np.ndarray)
else:
    Num = TypeVar("Num")


class Ops:
    """One set of elementary operations (all elementwise on arrays)."""

    __slots__ = ("hypot", "atan2", "atan", "sin", "wrap", "copysign", "maximum", "minimum", "where")

    def __init__(self, **fns: Callable[..., Any]):
        for name in self.__slots__:
            setattr(self, name, fns[name])

    # for the checker: each is a function of floats (SCALAR) or arrays (ARRAY)
    hypot: Callable[..., Any]
    atan2: Callable[..., Any]
    atan: Callable[..., Any]
    sin: Callable[..., Any]
    wrap: Callable[..., Any]  # to (-pi, pi], swarm.contracts.orbits.wrap
    copysign: Callable[..., Any]
    maximum: Callable[..., Any]  # max(a, b) of two
    minimum: Callable[..., Any]
    where: Callable[..., Any]  # where(cond, a, b): a where cond, else b


def _where(cond: bool, a: float, b: float) -> float:
    return a if cond else b


SCALAR = Ops(
    hypot=math.hypot,
    atan2=math.atan2,
    atan=math.atan,
    sin=math.sin,
    wrap=wrap,
    copysign=math.copysign,
    maximum=max,
    minimum=min,
    where=_where,
)
