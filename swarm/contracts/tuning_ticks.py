"""The sticky selection rule's tuning as agent processes hold it: plain values without pydantic
(agent processes stay small and start fast; the scenario's validated `SelectionTuning` is in
swarm/contracts/tuning.py, with its fields from `KNOBS` here), and `TuningTicks.of(tuning, dt)`,
the conversion to ticks, done once. Pure: no I/O.
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


class Knob(NamedTuple):
    """One tuning field: its default (today's value), its bounds (low exclusive, high
    inclusive) and what it means."""

    default: float
    low: float
    high: float
    description: str


# The one definition of the tuning's fields: TuningValues (agents) and the scenario's validated
# SelectionTuning (swarm/contracts/tuning.py) both take their defaults, bounds and words from it.
KNOBS: dict[str, Knob] = {
    "hold_s": Knob(5.0, 0.0, 3600.0, "s a follower keeps steering by an out-neighbour that lost its path (HOLD)"),
    "coast_s": Knob(
        5.0, 0.0, 3600.0, "s a follower steers by the predicted place of an out-neighbour that left at the edge (COAST)"
    ),
    "reach": Knob(
        0.85, 0.0, 1.0, "new choices within this fraction of the sensing range and of half the field of view"
    ),
    "edge": Knob(
        0.8,
        0.0,
        1.0,
        "a sighting at this fraction of the range (or half field of view) or beyond is at the edge "
        "(an out-neighbour last seen there may be coasted on)",
    ),
    "search_pitch": Knob(0.5, 0.0, 10.0, "the search spiral's pitch and first radius, in sensing ranges"),
    "search_first_out": Knob(
        4.0, 1.0, 1000.0, "the search spiral's first breath goes out to this many first radii, then back in"
    ),
    "search_growth": Knob(2.0, 1.0, 1000.0, "each later breath of the search spiral goes this many times further out"),
}


class TuningValues(NamedTuple):
    """A SelectionTuning's values (its defaults: today's), as a BrainConf carries them."""

    hold_s: float = KNOBS["hold_s"].default
    coast_s: float = KNOBS["coast_s"].default
    reach: float = KNOBS["reach"].default
    edge: float = KNOBS["edge"].default
    search_pitch: float = KNOBS["search_pitch"].default
    search_first_out: float = KNOBS["search_first_out"].default
    search_growth: float = KNOBS["search_growth"].default


DEFAULT = TuningValues()
# each field's bounds (low exclusive, high inclusive), as swarm/contracts/tuning.py validates them
LIMITS = {name: (k.low, k.high) for name, k in KNOBS.items()}


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
