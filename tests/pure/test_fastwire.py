"""The compiled hot path (swarm/contracts/_fastwire.c) against the pure-Python reference, to
the bit (tier pure), and the switch between them (swarm/contracts/fastpath.py).

- `encode_sense_tuples`, `encode_sense_rows`, `encode_sense_pairs`: the same bytes as the pure functions, for
  random frames (any float: NaN payloads, infinities, -0.0; ids and hops at their limits)
  and any rows (a subset, in any order, repeated);
- `decode_sense`: the same frame (the same objects: Contact tuples of int and float) or the
  same refusal, on valid, non-finite, overflowing, short and long frames;
- `nearest`: the very same contact object as the pure rule;
- where a C compiler exists, the compiled module was built (CI cannot silently test the
  pure path only); a module built for another API is not used.
"""

from __future__ import annotations

import math
import os
import shutil
import struct
import sys
import types

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm import contracts
from swarm.agents import selection
from swarm.contracts import fastpath, wire
from swarm.contracts.frames import Contact, SensorFrame

needs_c = pytest.mark.skipif(fastpath.compiled is None, reason=f"the compiled path is not in use: {fastpath.path}")
C = fastpath.compiled
SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

any_float = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
i32 = st.integers(-(2**31), 2**31 - 1)
i16 = st.integers(-(2**15), 2**15 - 1)
contact = st.tuples(i32, any_float, any_float, any_float, i16).map(lambda t: Contact(*t))


def test_a_machine_with_a_c_compiler_runs_the_compiled_path():
    """The install builds the module wherever a compiler exists (setup.py): here, unless the
    environment asked for the pure path."""
    if os.environ.get(fastpath.PURE_ENV) or os.environ.get("SWARM_NO_COMPILE"):
        pytest.skip("the pure path was asked for")
    if shutil.which(os.environ.get("CC", "cc")) is None:
        pytest.skip("no C compiler here")
    assert fastpath.compiled is not None, fastpath.path
    assert wire.decode_sense is not wire.decode_sense_py
    assert selection.nearest is not selection.nearest_py


def test_a_module_of_another_api_is_not_used(monkeypatch):
    """A compiled module built from an older checkout (pip install -e, then a pull): the pure
    path runs, and fastpath.path says why."""
    stale = types.ModuleType("swarm.contracts._fastwire")
    monkeypatch.setitem(sys.modules, "swarm.contracts._fastwire", stale)
    monkeypatch.setattr(contracts, "_fastwire", stale, raising=False)
    monkeypatch.delenv(fastpath.PURE_ENV, raising=False)
    module, why = fastpath._load()
    assert module is None and why.startswith("pure Python (the compiled module is of API 1"), why
    stale.API = fastpath.API  # type: ignore[attr-defined]
    assert fastpath._load()[0] is stale


# -- encoding -----------------------------------------------------------------------------------
@pytest.mark.slow
@needs_c
@SETTINGS
@given(
    st.integers(0, 2**63 - 1),
    any_float,
    i32,
    any_float,
    st.none() | st.tuples(any_float, any_float),
    st.lists(contact, max_size=40),
)
def test_encode_sense_tuples_gives_the_same_bytes(tick, time, agent, heading, target, contacts):
    want = wire.encode_sense_tuples_py(tick, time, agent, heading, target, contacts)
    assert wire.encode_sense_tuples(tick, time, agent, heading, target, contacts) == want
    assert wire.encode_sense_tuples(tick, time, agent, heading, target, tuple(contacts)) == want


@needs_c
def test_encode_sense_tuples_refuses_what_does_not_fit():
    for bad in ((2**31, 0.0, 0.0, 1.0, -1), (1, 0.0, 0.0, 1.0, 2**15)):
        with pytest.raises((OverflowError, struct.error)):
            wire.encode_sense_tuples_py(1, 0.0, 1, 0.0, None, [bad])
        with pytest.raises(OverflowError):
            wire.encode_sense_tuples(1, 0.0, 1, 0.0, None, [bad])
    with pytest.raises(TypeError):
        wire.encode_sense_tuples(1, 0.0, 1, 0.0, None, [(1, 0.0, 0.0)])


@st.composite
def world_arrays(draw):
    """The world's arrays for encode_sense_rows: N agents, rows (a subset in any order,
    possibly repeated), who senses whom, bearings and ranges (any floats)."""
    n = draw(st.integers(0, 30))
    seed = draw(st.integers(0, 2**32 - 1))
    rs = np.random.default_rng(seed)
    ids = rs.permutation(np.arange(1, 3 * n + 2, dtype=np.int64))[:n]
    if draw(st.booleans()):
        rows = np.arange(n)
    else:
        rows = rs.integers(0, max(n, 1), size=int(rs.integers(0, n + 2))) if n else np.arange(0)
    sensed = rs.random((n, n)) < draw(st.sampled_from([0.0, 0.3, 1.0]))
    specials = np.array([math.nan, math.inf, -math.inf, -0.0, 5e-324, 1e308])
    bearing = rs.normal(size=(n, n)) * 3
    ranges = rs.random((n, n)) * 100
    if n and draw(st.booleans()):
        bearing.flat[rs.integers(0, n * n, size=n)] = rs.choice(specials, size=n)
        ranges.flat[rs.integers(0, n * n, size=n)] = rs.choice(specials, size=n)
    heading = rs.normal(size=n)
    hops = rs.integers(-1, n + 1, size=n).astype(np.int64)
    lead = rs.random(n) < 0.3
    tdx, tdy = rs.normal(size=n) * 50, rs.normal(size=n) * 50
    return rows, ids, heading, tdx, tdy, lead, sensed, bearing, ranges, hops


@pytest.mark.slow
@needs_c
@SETTINGS
@given(st.integers(0, 2**40), st.floats(0, 1e6), world_arrays())
def test_encode_sense_rows_gives_the_same_bytes(tick, time, arrays):
    want = wire.encode_sense_rows_py(tick, time, *arrays)
    assert wire.encode_sense_rows(tick, time, *arrays) == want


@pytest.mark.slow
@needs_c
@SETTINGS
@given(st.integers(0, 2**40), st.floats(0, 1e6), world_arrays())
def test_encode_sense_pairs_gives_the_same_bytes(tick, time, arrays):
    """The sensed pairs of the same swarms (sorted by i, then j, as sensing_pairs gives them)."""
    rows, ids, heading, tdx, tdy, lead, sensed, bearing, ranges, hops = arrays
    i, j = np.nonzero(sensed)
    args = (rows, ids, heading, tdx, tdy, lead, i, j, bearing[i, j], ranges[i, j], hops)
    assert wire.encode_sense_pairs(tick, time, *args) == wire.encode_sense_pairs_py(tick, time, *args)


@needs_c
def test_encode_sense_pairs_refuses_pairs_out_of_order():
    args = ([0, 1], np.arange(2), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2, bool))
    with pytest.raises(ValueError):
        wire.encode_sense_pairs(1, 0.0, *args, [1, 0], [0, 1], [0.0, 0.0], [1.0, 1.0], np.full(2, -1))


@needs_c
def test_encode_sense_rows_takes_the_worlds_dtypes_as_they_come():
    """Rows as a list, ids as int32, a non-contiguous matrix: converted, the same bytes."""
    rs = np.random.default_rng(3)
    n = 9
    big = rs.random((n, 2 * n))
    args = (
        [4, 0, 8],
        np.arange(10, 10 + n, dtype=np.int32),
        rs.normal(size=n),
        rs.normal(size=n),
        rs.normal(size=n),
        rs.random(n) < 0.5,
        big[:, ::2] < 0.5,
        big[:, 1::2],
        big[:, ::2] * 10,
        np.full(n, -1),
    )
    assert wire.encode_sense_rows(7, 0.07, *args) == wire.encode_sense_rows_py(7, 0.07, *args)


# -- decoding -----------------------------------------------------------------------------------
def outcome(decode, buf: bytes):
    try:
        return decode(buf)
    except wire.WireError as e:
        return f"refused: {e}"


def same_objects(a, b) -> bool:
    """Equal frames made of the same types (Contact tuples of int and float)."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    if a != b or type(a.contacts) is not type(b.contacts) or wire.encode_sense(a) != wire.encode_sense(b):
        return False  # (the bytes again: -0.0 and 0.0 are equal, their bits are not)
    if hash(a) != hash(b) or [hash(c) for c in a.contacts] != [hash(tuple(c)) for c in a.contacts]:
        return False  # a tuple made in C hashes as one made in Python
    return all(
        type(x) is type(y) and [type(v) for v in x] == [type(v) for v in y] for x, y in zip(a.contacts, b.contacts)
    )


@pytest.mark.slow
@needs_c
@SETTINGS
@given(
    st.integers(-5, 2**40),
    any_float,
    i32,
    any_float,
    st.none() | st.tuples(any_float, any_float),
    st.lists(contact, max_size=30),
    st.sampled_from(["as is", "short", "long", "count", "kind", "version"]),
)
def test_decode_sense_gives_the_same_frame_or_refusal(tick, time, agent, heading, target, contacts, how):
    """The same frame or the same refusal; and the C decoder alone takes exactly the frames
    the reference takes (what it refuses, the reference decodes again to say why)."""
    buf = bytearray(wire.encode_sense_tuples_py(max(tick, 0), time, agent, heading, target, contacts))
    if tick < 0:
        struct.pack_into("<q", buf, 8, tick)
    if how == "short":
        buf = buf[: max(0, len(buf) - 1 - tick % 40)]
    elif how == "long":
        buf += b"\1" * (1 + tick % 40)
    elif how == "count":
        struct.pack_into("<I", buf, 48, (tick % 3) * wire.MAX_AGENTS)
    elif how in ("kind", "version"):
        buf[0 if how == "kind" else 1] ^= 1 + tick % 7
    got, want = outcome(wire.decode_sense, bytes(buf)), outcome(wire.decode_sense_py, bytes(buf))
    assert same_objects(got, want), (got, want)
    alone = C.decode_sense(bytes(buf), wire.KIND_SENSE, wire.VERSION, wire.MAX_AGENTS, Contact, SensorFrame)
    assert (alone is None) == isinstance(want, str), (alone, want)
    assert alone is None or same_objects(alone, want), (alone, want)


@needs_c
def test_finite_numbers_whose_sum_overflows_are_accepted_by_both():
    """The rule is every number finite, on any Python (3.12's sum() compensates, 3.11's does
    not: a rule on the sum would differ between them)."""
    big = 1.7976931348623157e308
    for contacts, target in (((Contact(2, big, big, 1.0, -1),), None), ((), (big, big))):
        frame = SensorFrame(3, 0.03, 1, big, contacts, target)
        buf = wire.encode_sense(frame)
        assert same_objects(wire.decode_sense(buf), frame) and same_objects(wire.decode_sense_py(buf), frame)


@needs_c
def test_decode_sense_refuses_a_type_that_is_no_tuple():
    with pytest.raises(TypeError, match="frame_type must be a tuple subclass"):
        C.decode_sense(b"", wire.KIND_SENSE, wire.VERSION, wire.MAX_AGENTS, Contact, list)
    assert C.decode_sense(b"\0" * 10, wire.KIND_SENSE, wire.VERSION, wire.MAX_AGENTS, Contact, SensorFrame) is None


@needs_c
def test_decode_sense_reads_nothing_past_the_buffer():
    """A count of contacts the buffer does not hold is refused, however large (with any limit:
    n * 30 must not wrap around), and so is a header cut short."""
    head = bytearray(wire.encode_sense_tuples_py(1, 0.01, 2, 0.0, None, [(3, 0.1, 0.2, 5.0, -1)] * 2))
    args = (wire.KIND_SENSE, wire.VERSION, 2**62, Contact, SensorFrame)
    assert C.decode_sense(bytes(head), *args) is not None
    for n in (3, 2**31, 2**32 - 1):
        struct.pack_into("<I", head, 48, n)
        assert C.decode_sense(bytes(head), *args) is None
    assert C.decode_sense(bytes(head[:51]), *args) is None


@needs_c
def test_encode_sense_tuples_is_safe_against_a_list_changed_while_encoding():
    """A number whose __float__ empties the list being encoded: encoded from a copy."""
    contacts: list = []

    class Sly(float):
        def __float__(self):
            contacts.clear()
            return 1.0

    contacts += [(1, Sly(1.0), 0.0, 1.0, -1), (2, 0.0, 0.0, 2.0, -1)]
    want = wire.encode_sense_tuples_py(1, 0.0, 1, 0.0, None, list(contacts))
    assert len(wire.encode_sense_tuples(1, 0.0, 1, 0.0, None, contacts)) == len(want)


# -- selection ----------------------------------------------------------------------------------
@pytest.mark.slow
@needs_c
@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(-3, 6), st.sampled_from([0.0, -0.0, 1.0, 1.0, 2.5, 1e-300, math.inf]))))
def test_nearest_is_the_same_contact_object(raw):
    contacts = tuple(Contact(i, 0.0, 0.0, r, -1) for i, r in raw)
    assert selection.nearest(contacts) is selection.nearest_py(contacts)


@needs_c
def test_nearest_leaves_what_it_does_not_know_to_the_reference():
    odd = (Contact(1, 0.0, 0.0, math.nan, -1), Contact(2, 0.0, 0.0, 1.0, -1))
    assert selection.nearest(odd) is selection.nearest_py(odd)
    ints = (Contact(1, 0.0, 0.0, 3, -1), Contact(2, 0.0, 0.0, 1, -1))  # ranges as ints
    assert selection.nearest(ints) is ints[1]
    assert selection.nearest(list(ints)) is ints[1]  # type: ignore[arg-type]
    assert selection.nearest(()) is None
