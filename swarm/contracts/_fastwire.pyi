"""Types of the compiled hot path (swarm/contracts/_fastwire.c); see fastpath.py."""

from collections.abc import Sequence
from typing import Any

API: int

def encode_sense_tuples(
    tick: int, time: float, agent: int, heading: float, target: tuple[float, float] | None, contacts: Sequence[tuple]
) -> bytes: ...
def encode_sense_rows(
    tick: int,
    time: float,
    rows: Any,
    ids: Any,
    heading: Any,
    target_dx: Any,
    target_dy: Any,
    is_leader: Any,
    sensed: Any,
    bearing: Any,
    ranges: Any,
    hops: Any,
) -> list[bytes]: ...
def encode_sense_pairs(
    tick: int,
    time: float,
    rows: Any,
    ids: Any,
    heading: Any,
    target_dx: Any,
    target_dy: Any,
    is_leader: Any,
    i: Any,
    j: Any,
    bearing: Any,
    ranges: Any,
    hops: Any,
) -> list[bytes]: ...
def decode_sense(
    buf: bytes, kind: int, version: int, max_agents: int, contact_type: type, frame_type: type
) -> Any | None: ...
def nearest(contacts: tuple) -> Any: ...
