"""The tuning of the sticky selection rule (docs/design/selection.md#tuning): one frozen
object in seconds and fractions, a scenario's optional `[sensing.tuning]` table.

`SelectionTuning` holds what a user may set, with today's values as defaults: a scenario
without the table runs exactly as before. Its fields' defaults, bounds and descriptions are
swarm/contracts/tuning_ticks.py's `KNOBS`, which the agents' plain `TuningValues` takes too.
`TuningTicks.of(tuning, dt)` converts it to ticks once, for the follower's state machine
(agents/sticky.Sticky), its coasting (agents/coast.py) and its search (agents/search.py). Pure: no I/O.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from swarm.contracts.tuning_ticks import KNOBS, TuningTicks, ticks

__all__ = ["SelectionTuning", "TuningTicks", "ticks"]


def _knob(name: str) -> Any:
    """The field `name` as swarm/contracts/tuning_ticks.py's KNOBS defines it (default, bounds, words)."""
    k = KNOBS[name]
    return Field(default=k.default, gt=k.low, le=k.high, allow_inf_nan=False, description=k.description)


class SelectionTuning(BaseModel):
    """[sensing.tuning]: the sticky rule's spells (s) and margins (fractions)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    hold_s: float = _knob("hold_s")
    coast_s: float = _knob("coast_s")
    reach: float = _knob("reach")
    edge: float = _knob("edge")
    search_pitch: float = _knob("search_pitch")
    search_first_out: float = _knob("search_first_out")
    search_growth: float = _knob("search_growth")
