"""What an agent's sensors give it at one tick. Named tuples, no numpy: agent processes
stay small, and decoding a frame of 49 contacts takes ~8 us instead of ~23 us with frozen
dataclasses (docs/benchmarks.md#optimisations)."""

from __future__ import annotations

from typing import NamedTuple


class Contact(NamedTuple):
    """One sensed agent, as agent i sees it."""

    id: int
    bearing: float  # line-of-sight angle lambda_ij from i to j, world frame (rad)
    heading: float  # heading g_j of the sensed agent (rad)
    range: float  # distance r_ij (m); only for ranking candidates
    hops: int = -1  # hops to a leader that agent last advertised (-1: none / not rooted)


class SensorFrame(NamedTuple):
    """Everything agent `agent` learns at tick `tick`."""

    tick: int
    time: float  # simulated time of the tick (s)
    agent: int
    heading: float  # own heading (rad)
    contacts: tuple[Contact, ...]  # in scenario order
    target: tuple[float, float] | None = None  # leaders: target minus own position (m)
