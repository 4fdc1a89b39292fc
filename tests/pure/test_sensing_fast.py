"""The hot path's fast forms against their references, to the bit (tier pure).

- who senses whom through the grid (world/sensing.py `sensing_pairs`, `sensing_grid`)
  against every pair (`sensing_matrix`): the same sensed pairs, bearings and ranges, on
  random swarms, ranges, fields of view and presence masks; the world core picks the grid
  from GRID_MIN_AGENTS agents with a range and its frames stay those of the reference;
- frames encoded from flat indices (`wire.encode_sense_rows`) and from sensed pairs
  (`wire.encode_sense_pairs`) against one `encode_sense` per frame built by `build_frames`;
- frames decoded with one unpack (`wire.decode_sense`) against the record-by-record decoder
  it replaced, valid and malformed;
- `selection.nearest` (min in C) against the Python loop it replaced.
"""

from __future__ import annotations

import functools
import math
import struct
import tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm.agents.selection import nearest
from swarm.contracts import wire
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.scenario import parse_scenario
from swarm.world.core import WorldCore
from swarm.world.sensing import (
    GRID_MAX_CELLS,
    GRID_MIN_AGENTS,
    build_frames,
    pairs_matrices,
    sensing_grid,
    sensing_matrix,
    sensing_pairs,
)

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def bits(a) -> bytes:
    """The bytes of an array of floats: equal bits, -0.0 and NaN payloads included."""
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def reference_pairs(x, y, g, present, sense_range, fov):
    s, bearing, rng = sensing_matrix(x, y, g, present, sense_range, fov)
    i, j = np.nonzero(s)
    return s, i, j, bearing[i, j], rng[i, j]


def assert_same_sensing(x, y, g, present, sense_range, fov):
    s, i, j, b, r = reference_pairs(x, y, g, present, sense_range, fov)
    gi, gj, gb, gr = sensing_pairs(x, y, g, present, sense_range, fov)
    assert gi.tolist() == i.tolist() and gj.tolist() == j.tolist()
    assert bits(gb) == bits(b) and bits(gr) == bits(r)
    gs, gbm, grm = sensing_grid(x, y, g, present, sense_range, fov)
    assert (gs == s).all()
    assert bits(gbm[s]) == bits(b) and bits(grm[s]) == bits(r)
    assert np.isnan(gbm[~s]).all() and np.isinf(grm[~s]).all()


@st.composite
def swarms(draw, max_n: int = 70):
    """A swarm: positions spread (or heaped) at some scale around some offset, headings,
    who is present; a range at some fraction of the spread (sometimes 0, or beyond it) and
    a field of view (none, some, a whole turn or more)."""
    n = draw(st.integers(0, max_n))
    seed = draw(st.integers(0, 2**32 - 1))
    rs = np.random.default_rng(seed)
    scale = draw(st.sampled_from([1e-3, 1.0, 30.0, 1e3]))
    offset = draw(st.sampled_from([0.0, -37.5, 1e4, 3e6]))
    x = offset + scale * rs.uniform(-1, 1, n)
    y = -offset + scale * rs.uniform(-1, 1, n)
    if n > 3 and draw(st.booleans()):  # agents on one spot, on one line, on cell-sized steps
        x[1], y[1] = x[0], y[0]
        y[2] = y[3]
    if n > 4 and draw(st.booleans()):
        step = draw(st.sampled_from([0.5, 1.0, 2.0]))
        x[: n // 2] = offset + step * np.arange(n // 2)
    g = rs.uniform(-math.pi, math.pi, n)
    present = rs.random(n) < draw(st.sampled_from([1.0, 0.9, 0.5]))
    sense_range = scale * draw(st.sampled_from([0.0, 1e-9, 0.05, 0.2, 0.5, 1.0, 3.0]))
    if draw(st.booleans()):
        sense_range = float(np.hypot(x[1] - x[0], y[1] - y[0])) if n > 1 else sense_range  # a pair at the limit
    fov = draw(st.sampled_from([None, 0.3, 2.0, math.pi, 2 * math.pi, 7.0]))
    return x, y, g, present, sense_range, fov


@pytest.mark.slow
@SETTINGS
@given(swarms())
def test_grid_senses_what_every_pair_senses(swarm):
    """The same pairs, bearings and ranges to the bit, whatever the swarm, range and field of view."""
    assert_same_sensing(*swarm)


@pytest.mark.parametrize(
    "case",
    [
        "range 0",  # no cell size: every pair
        "a swarm wider than the grid",
        "a position not finite",
        "one agent",
        "nobody present",
    ],
)
def test_grid_falls_back_to_every_pair_where_no_grid_fits(case):
    rs = np.random.default_rng(3)
    n = 12
    x, y, g = rs.uniform(-5, 5, n), rs.uniform(-5, 5, n), rs.uniform(-3, 3, n)
    present = np.ones(n, dtype=bool)
    sense_range = 2.0
    if case == "range 0":
        sense_range = 0.0
        x[1], y[1] = x[0], y[0]
    elif case == "a swarm wider than the grid":
        x[0] = 3.0 * GRID_MAX_CELLS * sense_range
    elif case == "a position not finite":
        x[0] = math.inf
    elif case == "one agent":
        present[1:] = False
    else:
        present[:] = False
    with np.errstate(invalid="ignore"):  # inf - inf in the reference
        assert_same_sensing(x, y, g, present, sense_range, None)
        assert_same_sensing(x, y, g, present, sense_range, 2.5)


@pytest.mark.slow
def test_the_grid_on_a_large_swarm_with_about_eight_in_sight():
    """1000 agents, a range with about 8 in sight, some absent, a field of view."""
    rs = np.random.default_rng(11)
    n = 1000
    r, t = 300.0 * np.sqrt(rs.random(n)), rs.uniform(0, 2 * math.pi, n)
    x, y, g = r * np.cos(t), r * np.sin(t), rs.uniform(-math.pi, math.pi, n)
    present = rs.random(n) < 0.95
    sense_range = 300.0 * math.sqrt(8 / n)
    assert_same_sensing(x, y, g, present, sense_range, None)
    assert_same_sensing(x, y, g, present, sense_range, 4.0)
    assert 6 < len(sensing_pairs(x, y, g, present, sense_range, None)[0]) / n < 10


def ring_scenario(n: int, sense_range: float | None, fov: float | None = None):
    lines = ["[run]", "dt = 0.01", "duration = 1.0", "[target]", "x = 0.0", "y = 0.0", "[gains]", "c1 = 1.0"]
    lines += ["c2 = 0.5", "[sensing]"]
    lines += ['selection = "nearest"'] + ([f"range = {sense_range}"] if sense_range else [])
    lines += [f"fov = {fov}"] if fov else []
    for k in range(n):
        a = 2 * math.pi * k / n
        lines += ["[[agents]]", f"id = {k + 1}", f"x = {30 * math.cos(a) + (k % 3)}", f"y = {30 * math.sin(a)}"]
        lines += [f"heading = {a + 1.5}", "speed = 1.0"]
        lines += ['role = "leader"', "orbit_radius = 20.0"] if k == 0 else ['role = "follower"']
    return parse_scenario(tomllib.loads("\n".join(lines)))


@pytest.mark.slow
@pytest.mark.parametrize(
    "n, sense_range, fov",
    [
        (GRID_MIN_AGENTS, 9.0, None),
        (GRID_MIN_AGENTS + 30, 6.0, 3.0),
        (GRID_MIN_AGENTS - 1, 6.0, None),
        (150, None, None),
    ],
)
def test_the_world_core_senses_through_the_grid_from_its_threshold(n, sense_range, fov):
    """WorldCore.sensing: the grid with a range from GRID_MIN_AGENTS agents (its frames are
    those of every pair), every pair without a range; an agent dropped or gone changes both alike."""
    core = WorldCore(ring_scenario(n, sense_range, fov))
    for _ in range(3):
        s, bearing, rng = core.sensing()
        ref = sensing_matrix(core.x, core.y, core.heading, core.present_mask(), sense_range, fov)
        assert (s == ref[0]).all()
        assert bits(bearing[s]) == bits(ref[1][s]) and bits(rng[s]) == bits(ref[2][s])
        if sense_range is None or n < GRID_MIN_AGENTS:
            assert bits(bearing) == bits(ref[1]) and bits(rng) == bits(ref[2])  # the reference itself
        else:
            assert np.isinf(rng[~s]).all()  # the grid's
        got = core.frames()
        want = build_frames(
            core.tick,
            core.time,
            core.ids,
            core.x,
            core.y,
            core.heading,
            core.present_mask(),
            [core.index[a] for a in core.active_ids()],
            core.is_leader,
            core.target,
            sense_range,
            fov,
            core.hops,
        )
        assert got == want
        core.drop(int(core.ids[3]))
        core.step()


@st.composite
def frames_inputs(draw):
    x, y, g, present, sense_range, fov = draw(swarms(max_n=40))
    n = len(x)
    rs = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    ids = rs.permutation(np.arange(1, 5 * n + 2))[:n].astype(np.int64)
    lead = rs.random(n) < 0.2
    hops = rs.integers(-1, 6, n).astype(np.int64)
    live = [k for k in range(n) if present[k]]
    rows = draw(st.sampled_from(["all present", "some", "shuffled"]))
    if rows == "some":
        live = [k for k in live if rs.random() < 0.7]
    elif rows == "shuffled":
        live = rs.permutation(np.array(live, dtype=np.int64)).tolist()
    unlimited = draw(st.booleans())
    return x, y, g, present, None if unlimited else sense_range, fov, ids, lead, hops, live


@pytest.mark.slow
@SETTINGS
@given(frames_inputs())
def test_frames_encoded_from_flat_indices_and_from_pairs_are_the_frames_built_one_by_one(inputs):
    """encode_sense_rows (the reference's matrices, the grid's) and encode_sense_pairs send the
    bytes of one encode_sense per frame: all agents, some, in any order, leaders and not."""
    x, y, g, present, sense_range, fov, ids, lead, hops, rows = inputs
    target = (1.5, -2.0)
    tdx, tdy = target[0] - x, target[1] - y
    built = build_frames(9, 0.09, ids, x, y, g, present, rows, lead, target, sense_range, fov, hops)
    want = [wire.encode_sense(built[int(ids[k])]) for k in rows]
    s, bearing, rng = sensing_matrix(x, y, g, present, sense_range, fov)
    assert wire.encode_sense_rows(9, 0.09, rows, ids, g, tdx, tdy, lead, s, bearing, rng, hops) == want
    i, j = np.nonzero(s)
    pairs = (i, j, bearing[i, j], rng[i, j])
    assert wire.encode_sense_pairs(9, 0.09, rows, ids, g, tdx, tdy, lead, *pairs, hops) == want
    if sense_range is not None:
        grid = sensing_grid(x, y, g, present, sense_range, fov)
        assert wire.encode_sense_rows(9, 0.09, rows, ids, g, tdx, tdy, lead, *grid, hops) == want
        gp = sensing_pairs(x, y, g, present, sense_range, fov)
        assert wire.encode_sense_pairs(9, 0.09, rows, ids, g, tdx, tdy, lead, *gp, hops) == want


def test_pairs_matrices_put_the_pairs_in_place():
    s, b, r = pairs_matrices(3, np.array([0, 2]), np.array([1, 0]), np.array([0.5, -1.0]), np.array([2.0, 3.0]))
    assert s.tolist() == [[False, True, False], [False, False, False], [True, False, False]]
    assert b[0, 1] == 0.5 and b[2, 0] == -1.0 and r[0, 1] == 2.0 and r[2, 0] == 3.0
    assert np.isnan(b[1, 1]) and np.isinf(r[1, 2])


# -- decoding -----------------------------------------------------------------------------------
_contact = functools.partial(tuple.__new__, Contact)


def reference_decode(buf: bytes) -> SensorFrame:
    """wire.decode_sense as it was before the one-unpack form (record by record)."""
    f = wire._check_head(buf, wire.SENSE_HEAD, wire.KIND_SENSE, "sense frame")
    _, _, has_t, _, agent, tick, time, heading, tx, ty, n = f
    if n > wire.MAX_AGENTS:
        raise wire.WireError("too many")
    if len(buf) != wire.SENSE_HEAD.size + n * wire.CONTACT.size:
        raise wire.WireError("length")
    contacts = tuple(map(_contact, wire.CONTACT.iter_unpack(memoryview(buf)[wire.SENSE_HEAD.size :])))
    total = time + heading + (tx + ty if has_t else 0.0) + sum(map(sum, contacts))
    if not math.isfinite(total):
        raise wire.WireError("non-finite")
    if tick < 0:
        raise wire.WireError("tick")
    return SensorFrame(tick, time, agent, heading, contacts, (tx, ty) if has_t else None)


def outcome(decode, buf: bytes):
    try:
        return decode(buf)
    except wire.WireError:
        return "refused"


BAD = [math.nan, math.inf, -math.inf]


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from([0, 1, 2, 7, 99, wire.CONTACTS_CACHED, wire.CONTACTS_CACHED + 1]),
    st.integers(0, 2**32 - 1),
    st.sampled_from(["valid", "non-finite", "short", "long", "negative tick", "leader"]),
)
def test_decoding_in_one_unpack_is_the_record_by_record_decoder(n, seed, how):
    """Frames of every size around the cached layouts, valid and malformed: the same frame
    or the same refusal (WireError, never another exception)."""
    rs = np.random.default_rng(seed)
    contacts = tuple(
        Contact(int(rs.integers(0, 2**31 - 1)), float(rs.normal()), float(rs.normal()), float(rs.random() * 50), -1)
        for _ in range(n)
    )
    frame = SensorFrame(int(rs.integers(0, 10**6)), 0.01, 3, 0.5, contacts, (1.0, 2.0) if how == "leader" else None)
    buf = bytearray(wire.encode_sense(frame))
    if how == "non-finite":
        field = int(rs.integers(0, 3 + 3 * n))  # time, heading, a target offset or a contact's float
        if field < 2:
            struct.pack_into("<d", buf, 16 + 8 * field, BAD[seed % 3])
        elif field == 2:
            struct.pack_into("<Bd", buf, 2, 1, 0.0)  # has_target set ...
            struct.pack_into("<d", buf, 32, BAD[seed % 3])  # ... and its dx not finite
        else:
            k, f = divmod(field - 3, 3)
            if n == 0:
                return
            struct.pack_into("<d", buf, wire.SENSE_HEAD.size + k * wire.CONTACT.size + 4 + 8 * f, BAD[seed % 3])
    elif how == "short":
        buf = buf[: len(buf) - 1 - int(rs.integers(0, 20))]
    elif how == "long":
        buf += b"\0" * int(rs.integers(1, 40))
    elif how == "negative tick":
        struct.pack_into("<q", buf, 8, -int(rs.integers(1, 100)))
    got, want = outcome(wire.decode_sense, bytes(buf)), outcome(reference_decode, bytes(buf))
    assert got == want
    if how in ("valid", "leader"):
        assert got == frame


def test_a_frame_of_the_largest_size_decodes_uncached():
    contacts = tuple(Contact(k, 0.1, 0.2, 1.0 + k, k % 4 - 1) for k in range(2000))
    frame = SensorFrame(5, 0.05, 1, 0.1, contacts, None)
    assert wire.decode_sense(wire.encode_sense(frame)) == frame


# -- selection ----------------------------------------------------------------------------------
def reference_nearest(contacts):
    best = None
    for c in contacts:
        if best is None or (c.range, c.id) < (best.range, best.id):
            best = c
    return best


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), st.sampled_from([0.0, 1.0, 1.0, 2.5, 3.0]), st.integers(-1, 3))))
def test_nearest_is_the_loop_it_replaced(raw):
    """Ties in range (lowest id wins), equal contacts (the first wins), none at all."""
    contacts = tuple(Contact(i, 0.0, 0.0, r, h) for i, r, h in raw)
    assert nearest(contacts) is reference_nearest(contacts)


@pytest.mark.parametrize("n, sense_range, fov", [(GRID_MIN_AGENTS + 6, 4.0, 2.5), (12, 8.0, None), (70, None, None)])
def test_the_world_cores_sensed_pairs_encode_its_frames(n, sense_range, fov):
    """WorldCore.sensed_pairs (through the grid, or from the matrices) are the reference's
    sensed pairs, and encode_sense_pairs on them sends the frames of encode_sense_rows."""
    core = WorldCore(ring_scenario(n, sense_range, fov))
    for _ in range(3):
        _, i, j, b, r = reference_pairs(core.x, core.y, core.heading, core.present_mask(), sense_range, fov)
        gi, gj, gb, gr = core.sensed_pairs()
        assert gi.tolist() == i.tolist() and gj.tolist() == j.tolist() and bits(gb) == bits(b) and bits(gr) == bits(r)
        rows = [core.index[a] for a in core.active_ids()]
        head = (core.tick, core.time, rows, core.ids, core.heading, -core.x, -core.y, core.is_leader)
        got = wire.encode_sense_pairs(*head, *core.sensed_pairs(), core.hops)
        assert got == wire.encode_sense_rows(*head, *core.sensing(), core.hops)
        core.drop(int(core.ids[2]))
        core.step()
