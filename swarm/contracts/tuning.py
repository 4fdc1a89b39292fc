"""The tuning of the sticky selection rule (docs/design/selection.md#tuning): one frozen
object in seconds and fractions, a scenario's optional `[sensing.tuning]` table.

`SelectionTuning` holds what a user may set, with today's values as defaults: a scenario
without the table runs exactly as before. `TuningTicks.of(tuning, dt)` converts it to
ticks once, for the follower's state machine (agents/sticky.Sticky), its coasting
(agents/coast.py) and its search (agents/search.py). Pure: no I/O.
"""

from __future__ import annotations

import math
from typing import Annotated, NamedTuple

from pydantic import BaseModel, ConfigDict, Field

Seconds = Annotated[float, Field(gt=0, le=3600.0, allow_inf_nan=False)]
Fraction = Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
Factor = Annotated[float, Field(gt=1, le=1000.0, allow_inf_nan=False)]


class SelectionTuning(BaseModel):
    """[sensing.tuning]: the sticky rule's spells (s) and margins (fractions)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    hold_s: Seconds = Field(
        default=5.0, description="s a follower keeps steering by an out-neighbour that lost its path (HOLD)"
    )
    coast_s: Seconds = Field(
        default=5.0,
        description="s a follower steers by the predicted place of an out-neighbour that left at the edge (COAST)",
    )
    reach: Fraction = Field(
        default=0.85, description="new choices within this fraction of the sensing range and of half the field of view"
    )
    edge: Fraction = Field(
        default=0.8,
        description="a sighting at this fraction of the range (or half field of view) or beyond is at the edge "
        "(an out-neighbour last seen there may be coasted on)",
    )
    search_pitch: Annotated[float, Field(gt=0, le=10.0, allow_inf_nan=False)] = Field(
        default=0.5, description="the search spiral's pitch and first radius, in sensing ranges"
    )
    search_first_out: Factor = Field(
        default=4.0, description="the search spiral's first breath goes out to this many first radii, then back in"
    )
    search_growth: Factor = Field(
        default=2.0, description="each later breath of the search spiral goes this many times further out"
    )


def ticks(seconds: float, dt: float) -> int:
    """`seconds` in ticks of dt, at least 1 (a whole number of seconds / dt stays exact)."""
    return max(1, math.ceil(seconds / dt - 1e-9))


class TuningTicks(NamedTuple):
    """A SelectionTuning at a tick length: the spells in ticks, the fractions as they are."""

    hold: int  # ticks
    coast: int  # ticks
    reach: float
    edge: float
    search_pitch: float
    search_first_out: float
    search_growth: float

    @classmethod
    def of(cls, tuning: SelectionTuning, dt: float) -> TuningTicks:
        return cls(
            ticks(tuning.hold_s, dt),
            ticks(tuning.coast_s, dt),
            tuning.reach,
            tuning.edge,
            tuning.search_pitch,
            tuning.search_first_out,
            tuning.search_growth,
        )
