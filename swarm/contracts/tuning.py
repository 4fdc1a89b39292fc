"""The tuning of the sticky selection rule (docs/design/selection.md#tuning): one frozen
object in seconds and fractions, a scenario's optional `[sensing.tuning]` table.

`SelectionTuning` holds what a user may set, with today's values as defaults: a scenario
without the table runs exactly as before. `TuningTicks.of(tuning, dt)` converts it to
ticks once, for the follower's state machine (agents/sticky.Sticky), its coasting
(agents/coast.py) and its search (agents/search.py). Pure: no I/O.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from swarm.contracts.tuning_ticks import TuningTicks, ticks

__all__ = ["SelectionTuning", "TuningTicks", "ticks"]

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
