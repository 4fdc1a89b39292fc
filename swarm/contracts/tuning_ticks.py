"""The sticky selection rule's tuning as agent processes hold it: plain values without pydantic
(agent processes stay small and start fast; the scenario's validated `SelectionTuning` is in
swarm/contracts/tuning.py), and `TuningTicks.of(tuning, dt)`, the conversion to ticks, done
once. Pure: no I/O.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol


class Tuning(Protocol):
    """What a tuning gives (SelectionTuning, TuningValues): spells in s, fractions, factors."""

    @property
    def hold_s(self) -> float: ...
    @property
    def coast_s(self) -> float: ...
    @property
    def reach(self) -> float: ...
    @property
    def edge(self) -> float: ...
    @property
    def search_pitch(self) -> float: ...
    @property
    def search_first_out(self) -> float: ...
    @property
    def search_growth(self) -> float: ...


class TuningValues(NamedTuple):
    """A SelectionTuning's values (its defaults: today's), as a BrainConf carries them."""

    hold_s: float = 5.0
    coast_s: float = 5.0
    reach: float = 0.85
    edge: float = 0.8
    search_pitch: float = 0.5
    search_first_out: float = 4.0
    search_growth: float = 2.0


DEFAULT = TuningValues()
# each field's bounds (low exclusive, high inclusive), as swarm/contracts/tuning.py validates them
LIMITS = {
    "hold_s": (0.0, 3600.0),
    "coast_s": (0.0, 3600.0),
    "reach": (0.0, 1.0),
    "edge": (0.0, 1.0),
    "search_pitch": (0.0, 10.0),
    "search_first_out": (1.0, 1000.0),
    "search_growth": (1.0, 1000.0),
}


def tuning_values(d: object) -> TuningValues:
    """sensing.tuning of a join reply (absent: the defaults): known fields, finite positive
    numbers (within the bounds the scenario's table is validated against); ValueError names the field."""
    if d is None:
        return DEFAULT
    if not isinstance(d, dict):
        raise ValueError("sensing.tuning: expected an object")
    out = {}
    for k, v in d.items():
        if k not in TuningValues._fields:
            raise ValueError(f"sensing.tuning.{k}: not a field (fields: {', '.join(TuningValues._fields)})")
        low, high = LIMITS[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not low < v <= high:
            raise ValueError(f"sensing.tuning.{k}: expected a number in ({low:g}, {high:g}], got {v!r}")
        out[k] = float(v)
    return TuningValues(**out)


def ticks(seconds: float, dt: float) -> int:
    """`seconds` in ticks of dt, at least 1 (a whole number of seconds / dt stays exact)."""
    return max(1, math.ceil(seconds / dt - 1e-9))


class TuningTicks(NamedTuple):
    """A tuning at a tick length: the spells in ticks, the fractions as they are."""

    hold: int  # ticks
    coast: int  # ticks
    reach: float
    edge: float
    search_pitch: float
    search_first_out: float
    search_growth: float

    @classmethod
    def of(cls, tuning: Tuning, dt: float) -> TuningTicks:
        return cls(
            ticks(tuning.hold_s, dt),
            ticks(tuning.coast_s, dt),
            tuning.reach,
            tuning.edge,
            tuning.search_pitch,
            tuning.search_first_out,
            tuning.search_growth,
        )
