"""Array versions of the scalar helpers the brain uses, equal to them to the bit, and
`ARRAY`: the operations of agents/ops.py on arrays (the shared laws' array set).

The per-agent brain computes with `math` on Python floats; the batch brains
(agents/batch.py) compute with numpy on (B, N) arrays. Where the two libraries round
differently the batch side calls the `math` function per element, so that a batch run
equals the per-agent run instead of drifting from it by rounding:

- `wrap` is swarm.contracts.orbits.wrap_array, the array version of orbits.wrap
  (math.remainder, then (-pi, pi]), to the bit.
- `hypot`, `atan2`, `atan`: numpy's SIMD versions differ from libm's in the last bit on
  some inputs, so these call `math` per element (leaders only: a few per member).
- np.sin and math.sin agree (checked in tests/pure/test_batch.py on this machine's numpy).

Pure: no I/O, no state.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm.agents.ops import Ops
from swarm.contracts.orbits import wrap_array as wrap

_hypot = np.frompyfunc(math.hypot, 2, 1)
_atan2 = np.frompyfunc(math.atan2, 2, 1)
_atan = np.frompyfunc(math.atan, 1, 1)


def saturate(u: Any, limit: Any) -> np.ndarray:
    """max(-limit, min(limit, u)) elementwise; limit inf where the agent has none."""
    return np.maximum(-limit, np.minimum(limit, u))


def hypot(x: Any, y: Any) -> np.ndarray:
    return _hypot(x, y).astype(float)


def atan2(y: Any, x: Any) -> np.ndarray:
    return _atan2(y, x).astype(float)


def atan(x: Any) -> np.ndarray:
    return _atan(x).astype(float)


def take(a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """a[b, j[b, i]] for (B, N) arrays a and column indices j (clipped: mask the -1s)."""
    return a[np.arange(a.shape[0])[:, None], np.maximum(j, 0)]


#: agents/ops.py's operations on arrays, elementwise (with `math` per element where numpy's
#: rounding could differ): the shared laws' array set
ARRAY = Ops(
    hypot=hypot,
    atan2=atan2,
    atan=atan,
    sin=np.sin,
    wrap=wrap,
    copysign=np.copysign,
    maximum=np.maximum,
    minimum=np.minimum,
    where=np.where,
)
