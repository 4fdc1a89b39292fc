"""The wire format of a run: key expressions, payloads, units, versions. Nothing else
in the project builds a key or packs a payload; docs/reference/protocol.md describes the same.

Keys (every key of a run starts with `swarm/<run>`, so runs never hear each other):

    swarm/<run>/world/alive          liveliness token of the world process
    swarm/<run>/world/info           queryable (operator): run info (scenario, clock, tick, agents)
    swarm/<run>/world/admin          queryable (operator): pause / resume the clock, stop the run
    swarm/<run>/world/control        world -> all: run-wide notices (JSON), e.g. the end
    swarm/<run>/truth                world -> observers: ground truth of one tick (binary)
    swarm/<run>/events               world -> observers: one event (JSON)
    swarm/<run>/agent/<id>/alive     liveliness token of agent <id>'s process
    swarm/<run>/agent/<id>/sense     world -> agent <id>: its sensor frame (binary)
    swarm/<run>/agent/<id>/cmd       agent <id> -> world: its command (binary)
    swarm/<run>/agent/<id>/status    agent <id> -> operator: its status (JSON); also its queryable
    swarm/<run>/agent/<id>/ctl       operator -> agent <id>: {"kind": "signal", "signal": "KILL"}
    swarm/<run>/agent/<id>/join      queryable of the world: agent <id> claims its id, gets its brain

Who may send what on these keys is the hub's business (swarm/contracts/access.py).

Hot-path payloads (sense, cmd, truth) are little-endian binary records led by a kind
byte and a version byte; cold-path payloads are UTF-8 JSON objects with "v": 1.
Units: metres, seconds, radians, rad/s. Decoders reject anything malformed with
`WireError` (never another exception), including NaN/inf where a number must be finite.
"""

from __future__ import annotations

import functools
import json
import math
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import chain, starmap
from typing import Any, NamedTuple

from swarm.contracts.fastpath import compiled as _c
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.freetext import BY_CHARS, HOST_CHARS, TEXT_CHARS, printable
from swarm.contracts.vocabulary import AgentState, FollowState, Phase

VERSION = 1
# A join reply whose brain names laws other than the built-in ones ("law": [law] follower /
# leader / params) says version 2: an agent that does not read "law" refuses it (its strict
# version check) instead of flying the built-in laws in their place.
JOIN_REPLY_LAW_VERSION = 2
PREFIX = "swarm"
KIND_SENSE, KIND_CMD, KIND_TRUTH = 1, 2, 3
MAX_AGENTS = 10_000
MAX_JSON_BYTES = 1 << 20

RUN_ID_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
AGENT_ID_RE = re.compile(r"^(0|[1-9][0-9]{0,9})$")  # canonical decimal; ids fit the int32 wire fields
MAX_AGENT_ID = 2**31 - 1


class WireError(ValueError):
    """A payload or key that does not follow this protocol."""


# --- key expressions ------------------------------------------------------------------
def check_run_id(run: str) -> str:
    if not RUN_ID_RE.match(run):
        raise WireError(f"run id {run!r}: use 1-64 of A-Z a-z 0-9 _ . -")
    return run


def run_prefix(run: str) -> str:
    return f"{PREFIX}/{check_run_id(run)}"


def world_alive_key(run: str) -> str:
    return f"{run_prefix(run)}/world/alive"


def world_info_key(run: str) -> str:
    return f"{run_prefix(run)}/world/info"


def world_admin_key(run: str) -> str:
    return f"{run_prefix(run)}/world/admin"


def world_supervise_key(run: str) -> str:
    """Queryable of the world for the launcher's reports (agent exit, fault done): only the
    run's `supervisor` identity may query it (swarm/contracts/access.py)."""
    return f"{run_prefix(run)}/world/supervise"


def world_control_key(run: str) -> str:
    return f"{run_prefix(run)}/world/control"


def truth_key(run: str) -> str:
    return f"{run_prefix(run)}/truth"


def events_key(run: str) -> str:
    return f"{run_prefix(run)}/events"


def agent_key(run: str, agent: int | str, leaf: str) -> str:
    """Key of one agent's `leaf` (alive, sense, cmd, status, ctl, join); agent may be '*'."""
    return f"{run_prefix(run)}/agent/{agent}/{leaf}"


def run_of_key(key: str) -> str:
    """The run id inside any key of this protocol."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != PREFIX:
        raise WireError(f"not a swarm key: {key!r}")
    return parts[1]


def agent_of_key(key: str) -> int:
    """Agent id in `swarm/<run>/agent/<id>/...`."""
    parts = str(key).split("/")
    if len(parts) < 5 or parts[0] != PREFIX or parts[2] != "agent" or not AGENT_ID_RE.match(parts[3]):
        raise WireError(f"not an agent key: {key!r}")
    return int(parts[3])


# --- binary hot path --------------------------------------------------------------------
# sense: kind, version, has_target, reserved, agent, tick, time (s), heading (rad),
#        target dx, dy (m; NaN when absent), n contacts; then n contact records.
SENSE_HEAD = struct.Struct("<BBBBiqddddI")
CONTACT = struct.Struct("<idddh")  # id, bearing (rad), heading (rad), range (m), advertised hops (-1 none)
# cmd: kind, version, phase code, follow state code (FOLLOW_STATES; 0 none: the byte was reserved
#      and always 0 before, so the version did not change), agent, tick, u (rad/s),
#      out-neighbour (-1 none), advertised hops to a leader (-1 none), key (the claim key from
#      the join reply)
CMD = struct.Struct("<BBBBiqdihQ")
# truth: kind, version, sequence number (u16 in bytes 2-3, low byte first; 0: not numbered),
#        n agents, tick, time (s); then n agent records.
TRUTH_HEAD = struct.Struct("<BBBBIqd")
SEQ_MOD = 1 << 16  # truth and events are numbered 1, 2, ... 65535, 1, ... (0: not numbered)
TRUTH_FIELDS = [
    ("id", "<i4"),
    ("x", "<f8"),
    ("y", "<f8"),
    ("heading", "<f8"),
    ("u", "<f8"),
    ("out", "<i4"),
    ("state", "u1"),
]  # numpy dtype of one record

# the order is the wire code (a command's phase byte, the truth record's state byte)
PHASES = (Phase.TRACK, Phase.LOST, Phase.ARC1, Phase.ARC2, Phase.ORBIT, Phase.SHADOW, Phase.SEARCH)
# what an agent counts itself and reports in its status (non-negative integers; the world
# copies them into the run's summary): see docs/reference/outputs.md#summary
STATUS_COUNTERS = ("garbage", "nonfinite", "losses", "loss_switches_max")
STATES = (AgentState.ACTIVE, AgentState.COASTING, AgentState.GONE)
# the order is the wire code of a command's follow state byte (and the int8 codes of
# trajectory.npz's `follow`): NONE first, so that a sender writing 0 there says none
FOLLOW_STATES = (
    FollowState.NONE,
    FollowState.ACQUIRE,
    FollowState.KEEP,
    FollowState.HOLD,
    FollowState.COAST,
    FollowState.SHADOW,
    FollowState.SEARCH,
    FollowState.LOST,
    FollowState.LATE,
)
FOLLOW_CODE: dict[str, int] = {s: k for k, s in enumerate(FOLLOW_STATES)}


def _check_head(buf: bytes, head: struct.Struct, kind: int, what: str) -> tuple:
    if len(buf) < head.size:
        raise WireError(f"{what}: {len(buf)} bytes, shorter than its {head.size}-byte header")
    fields = head.unpack_from(buf)
    if fields[0] != kind:
        raise WireError(f"{what}: kind byte {fields[0]}, expected {kind}")
    if fields[1] != VERSION:
        raise WireError(f"{what}: protocol version {fields[1]}, this build speaks {VERSION}")
    return fields


def encode_sense(frame: SensorFrame) -> bytes:
    return encode_sense_tuples(frame.tick, frame.time, frame.agent, frame.heading, frame.target, frame.contacts)


def encode_sense_tuples_py(
    tick: int, time: float, agent: int, heading: float, target: tuple[float, float] | None, contacts: Any
) -> bytes:
    """encode_sense from plain values; contacts: (id, bearing, heading, range, hops) tuples
    (a Contact is one). The pure-Python reference of `encode_sense_tuples`."""
    tx, ty = target if target is not None else (math.nan, math.nan)
    head = SENSE_HEAD.pack(
        KIND_SENSE, VERSION, int(target is not None), 0, agent, tick, time, heading, tx, ty, len(contacts)
    )
    return head + b"".join(starmap(CONTACT.pack, contacts))


# encode_sense from plain values, compiled where it was built (swarm/contracts/fastpath.py):
# the same bytes; the compiled one takes contacts as tuples only (a Contact is one)
encode_sense_tuples = encode_sense_tuples_py if _c is None else _c.encode_sense_tuples


CONTACT_FIELDS = [
    ("id", "<i4"),
    ("bearing", "<f8"),
    ("heading", "<f8"),
    ("range", "<f8"),
    ("hops", "<i2"),
]  # == CONTACT


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
) -> list[bytes]:
    """encode_sense_rows_py, compiled where it was built (swarm/contracts/fastpath.py): the
    same bytes, written straight from the arrays (no copy of the matrices' rows)."""
    if _c is None:
        return encode_sense_rows_py(
            tick, time, rows, ids, heading, target_dx, target_dy, is_leader, sensed, bearing, ranges, hops
        )
    rows, ids, hops, heading, target_dx, target_dy, is_leader = _agent_columns(
        rows, ids, hops, heading, target_dx, target_dy, is_leader
    )
    sensed, bearing, ranges = _columns("?ff", sensed, bearing, ranges)
    return _c.encode_sense_rows(
        int(tick), float(time), rows, ids, heading, target_dx, target_dy, is_leader, sensed, bearing, ranges, hops
    )


def _columns(kinds: str, *arrays: Any) -> list:
    """The arrays as the compiled module reads them, C-contiguous: kind i int64, f float64,
    ? bool (no copy where they already are)."""
    import numpy as np  # lazy: agent processes import wire and never load numpy

    dtypes = {"i": np.int64, "f": np.float64, "?": np.bool_}
    return [np.ascontiguousarray(a, dtype=dtypes[k]) for k, a in zip(kinds, arrays)]


def _agent_columns(
    rows: Any, ids: Any, hops: Any, heading: Any, target_dx: Any, target_dy: Any, is_leader: Any
) -> list:
    return _columns("iiifff?", rows, ids, hops, heading, target_dx, target_dy, is_leader)


def encode_sense_rows_py(
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
) -> list[bytes]:
    """The encoded frames of the agents at indices `rows`, all at once, from the world's
    arrays: ids, heading, hops, is_leader and the target's offset from each agent
    (target_dx, target_dy) are (N,); sensed, bearing and ranges (N, N). The same bytes as
    one encode_sense per agent, in one numpy pass over every sensed pair (flat
    indices into the matrices: no (N, N) copy when `rows` is every agent in order)."""
    import numpy as np  # lazy: agent processes import wire and never load numpy

    n = len(ids)
    rows = np.asarray(rows, dtype=np.int64)
    if len(rows) != n or (n and not (rows == np.arange(n)).all()):
        sensed, bearing, ranges = sensed[rows], bearing[rows], ranges[rows]
    flat = np.flatnonzero(sensed)  # row by row, as np.nonzero
    j = flat % n if n else flat
    recs = np.empty(len(flat), dtype=np.dtype(CONTACT_FIELDS))
    recs["id"], recs["heading"], recs["hops"] = ids[j], heading[j], hops[j]
    recs["bearing"], recs["range"] = bearing.ravel()[flat], ranges.ravel()[flat]
    return _sense_frames(tick, time, rows, ids, heading, target_dx, target_dy, is_leader, recs.tobytes(), sensed.sum(1))


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
) -> list[bytes]:
    """encode_sense_pairs_py, compiled where it was built (swarm/contracts/fastpath.py): the
    same bytes, each frame written straight from the pairs."""
    if _c is None:
        return encode_sense_pairs_py(
            tick, time, rows, ids, heading, target_dx, target_dy, is_leader, i, j, bearing, ranges, hops
        )
    rows, ids, hops, heading, target_dx, target_dy, is_leader = _agent_columns(
        rows, ids, hops, heading, target_dx, target_dy, is_leader
    )
    i, j, bearing, ranges = _columns("iiff", i, j, bearing, ranges)
    return _c.encode_sense_pairs(
        int(tick), float(time), rows, ids, heading, target_dx, target_dy, is_leader, i, j, bearing, ranges, hops
    )


def encode_sense_pairs_py(
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
) -> list[bytes]:
    """encode_sense_rows from the sensed pairs instead of (N, N) matrices: agent i senses
    agent j at `bearing`, `ranges` (arrays of the pairs, sorted by i, then j, as
    swarm.world.sensing.sensing_pairs gives them; pairs of agents not in `rows` are left
    out). The same bytes, in O(rows + pairs)."""
    import numpy as np  # lazy: agent processes import wire and never load numpy

    n = len(ids)
    rows = np.asarray(rows, dtype=np.int64)
    want = np.zeros(n, dtype=bool)
    want[rows] = True
    if not want[i].all():
        keep = want[i]
        i, j, bearing, ranges = i[keep], j[keep], bearing[keep], ranges[keep]
    recs = np.empty(len(j), dtype=np.dtype(CONTACT_FIELDS))
    recs["id"], recs["heading"], recs["hops"] = ids[j], heading[j], hops[j]
    recs["bearing"], recs["range"] = bearing, ranges
    counts = np.bincount(i, minlength=n)
    blob = recs.tobytes()
    if len(rows) > 1 and not (rows[1:] > rows[:-1]).all():  # not ascending: each row's run of pairs apart
        starts = (np.cumsum(counts) - counts)[rows]
        size = CONTACT.size
        parts = [blob[s * size : (s + c) * size] for s, c in zip(starts.tolist(), counts[rows].tolist())]
        blob = b"".join(parts)
    return _sense_frames(tick, time, rows, ids, heading, target_dx, target_dy, is_leader, blob, counts[rows])


def _sense_frames(
    tick: int,
    time: Any,
    rows: Any,
    ids: Any,
    heading: Any,
    target_dx: Any,
    target_dy: Any,
    is_leader: Any,
    blob: Any,
    counts: Any,
) -> list[bytes]:
    """One frame per row: its header, then its `counts` contact records from `blob` (the
    rows' records one after another)."""
    ids_l, head_l, lead_l = ids.tolist(), heading.tolist(), is_leader.tolist()
    dx_l, dy_l = target_dx.tolist(), target_dy.tolist()
    out, start, size, pack, nan = [], 0, CONTACT.size, SENSE_HEAD.pack, math.nan
    for k, c in zip(rows.tolist(), counts.tolist()):
        lead = lead_l[k]
        end = start + c * size
        out.append(
            pack(
                KIND_SENSE,
                VERSION,
                int(lead),
                0,
                ids_l[k],
                tick,
                time,
                head_l[k],
                dx_l[k] if lead else nan,
                dy_l[k] if lead else nan,
                c,
            )
            + blob[start:end]
        )
        start = end
    return out


_contact = functools.partial(tuple.__new__, Contact)  # Contact from a tuple, in C (Contact._make is Python)


CONTACTS_CACHED = 256  # frames of up to this many contacts are decoded with a layout kept per size


@functools.lru_cache(maxsize=64)
def _contacts_struct(n: int) -> struct.Struct:
    """The layout of n contact records one after another (CONTACT, n times; at most 64 sizes
    kept, each under 31 kB)."""
    return struct.Struct("<" + CONTACT.format.lstrip("<") * n)


def _all_finite(numbers: Sequence[float]) -> bool:
    """Whether every number is finite: their sum is not if one is NaN or infinite; only when the
    sum is not finite (one is, or finite numbers near 1e308 overflowed it) each is tested."""
    return math.isfinite(sum(numbers)) or all(map(math.isfinite, numbers))


def decode_sense_py(buf: bytes) -> SensorFrame:
    """A sensor frame from its bytes (WireError for anything that is not a valid one): the
    pure-Python reference of `decode_sense`."""
    _, _, has_t, _, agent, tick, time, heading, tx, ty, n = _check_head(buf, SENSE_HEAD, KIND_SENSE, "sense frame")
    if n > MAX_AGENTS:
        raise WireError(f"sense frame: {n} contacts, more than {MAX_AGENTS}")
    expected = SENSE_HEAD.size + n * CONTACT.size
    if len(buf) != expected:
        raise WireError(f"sense frame: {len(buf)} bytes, expected {expected} for {n} contacts")
    # Every contact's numbers in one unpack, grouped five by five into Contacts in C (zip
    # over one iterator); every number must be finite (`_all_finite`; the ids and hops among
    # them are integers, finite by construction).
    numbers: Sequence[float]
    if n <= CONTACTS_CACHED:
        numbers = _contacts_struct(n).unpack_from(buf, SENSE_HEAD.size)
        it = iter(numbers)
        contacts = tuple(map(_contact, zip(it, it, it, it, it)))
    else:  # no layout of its own kept for every size of a large frame
        contacts = tuple(map(_contact, CONTACT.iter_unpack(memoryview(buf)[SENSE_HEAD.size :])))
        numbers = list(chain.from_iterable(contacts))
    if not (_all_finite((time, heading, tx, ty) if has_t else (time, heading)) and _all_finite(numbers)):
        raise WireError("sense frame: non-finite number")
    if tick < 0:
        raise WireError(f"sense frame: negative tick {tick}")
    return SensorFrame(tick, time, agent, heading, contacts, (tx, ty) if has_t else None)


def _decode_sense_c(buf: bytes) -> SensorFrame:
    """decode_sense_py in C: the same frame for a valid one; anything the C decoder refuses is
    decoded again by decode_sense_py, which raises the WireError that says why."""
    assert _c is not None
    frame = _c.decode_sense(buf, KIND_SENSE, VERSION, MAX_AGENTS, Contact, SensorFrame)
    return decode_sense_py(buf) if frame is None else frame


# A sensor frame from its bytes, compiled where it was built (swarm/contracts/fastpath.py)
decode_sense = decode_sense_py if _c is None else _decode_sense_c


class Command(NamedTuple):
    """An agent's answer to its frame (a named tuple: the world decodes one per agent per tick,
    and a tuple is made in C, a frozen dataclass field by field)."""

    agent: int
    tick: int
    u: float  # rad/s
    out: int | None
    phase: str
    hops: int | None = None  # advertised hops to a leader
    key: int = 0  # the claim key the world gave this agent's process (proves who sends)
    follow: str = FollowState.NONE  # a FollowState: the follower's selection state (none: leaders, other rules)


_command = functools.partial(tuple.__new__, Command)  # Command from a tuple, in C


def encode_cmd(c: Command) -> bytes:
    return encode_cmd_fields(c.agent, c.tick, c.u, c.out, c.phase, c.hops, c.key, c.follow)


_PHASE_CODE: dict[str, int] = {p: k for k, p in enumerate(PHASES)}


_pack_cmd = CMD.pack  # bound once: the agent's path packs a command every tick


def encode_cmd_fields(
    agent: int,
    tick: int,
    u: float,
    out: int | None,
    phase: str,
    hops: int | None,
    key: int,
    follow: str = FollowState.NONE,
) -> bytes:
    """encode_cmd without making a Command first (an agent's path every tick)."""
    return _pack_cmd(
        KIND_CMD,
        VERSION,
        _PHASE_CODE[phase],
        FOLLOW_CODE[follow],
        agent,
        tick,
        u,
        -1 if out is None else out,
        -1 if hops is None else hops,
        key,
    )


def decode_cmd(buf: bytes) -> Command:
    if len(buf) != CMD.size:
        raise WireError(f"command: {len(buf)} bytes, expected {CMD.size}")
    kind, version, phase, follow, agent, tick, u, out, hops, key = CMD.unpack(buf)
    if kind != KIND_CMD or version != VERSION:
        _check_head(buf, CMD, KIND_CMD, "command")  # raises, saying which
    if not math.isfinite(u):
        raise WireError("command: non-finite turn rate")
    if phase >= len(PHASES):
        raise WireError(f"command: unknown phase code {phase}")
    if follow >= len(FOLLOW_STATES):
        raise WireError(f"command: unknown follow state code {follow}")
    if tick < 0:
        raise WireError(f"command: negative tick {tick}")
    return _command(
        (
            agent,
            tick,
            u,
            None if out < 0 else out,
            PHASES[phase],
            None if hops < 0 else hops,
            key,
            FOLLOW_STATES[follow],
        )
    )


def next_seq(seq: int) -> int:
    """The sequence number after `seq` on a numbered stream (truth, events): 1 after 65535
    (and after 0, not numbered), so that 0 never numbers a message."""
    return seq % (SEQ_MOD - 1) + 1


def encode_truth(
    tick: int, time: float, ids: Any, x: Any, y: Any, heading: Any, u: Any, out: Any, states: list[str], seq: int = 0
) -> bytes:
    """`seq`: the message's sequence number (`next_seq`; 0: not numbered), so that an observer
    can count messages that did not reach it (`truth_seq`)."""
    import numpy as np  # lazy: agent processes import wire and never load numpy

    recs = np.empty(len(ids), dtype=np.dtype(TRUTH_FIELDS))
    recs["id"], recs["x"], recs["y"], recs["heading"] = ids, x, y, heading
    recs["u"], recs["out"] = u, out
    recs["state"] = [STATES.index(s) for s in states]
    if not 0 <= seq < SEQ_MOD:
        raise WireError(f"truth: sequence number {seq} out of 0..{SEQ_MOD - 1}")
    return TRUTH_HEAD.pack(KIND_TRUTH, VERSION, seq & 0xFF, seq >> 8, len(ids), tick, time) + recs.tobytes()


def truth_seq(buf: bytes) -> int:
    """A truth message's sequence number (bytes 2-3; 0: not numbered, as by a world before
    numbering). Not checked: decode_truth checks the message."""
    return buf[2] | buf[3] << 8 if len(buf) >= 4 else 0


def decode_truth(buf: bytes) -> Any:
    """(tick, time, records): records is a numpy structured array with TRUTH_FIELDS."""
    import numpy as np  # lazy: agent processes import wire and never load numpy

    dtype = np.dtype(TRUTH_FIELDS)
    _, _, _, _, n, tick, time = _check_head(buf, TRUTH_HEAD, KIND_TRUTH, "truth")
    if n > MAX_AGENTS or len(buf) != TRUTH_HEAD.size + n * dtype.itemsize:
        raise WireError(f"truth: {len(buf)} bytes do not hold {n} agent records")
    return tick, time, np.frombuffer(buf, dtype=dtype, count=n, offset=TRUTH_HEAD.size)


# --- JSON cold path ----------------------------------------------------------------------
def _reject_constant(name: str) -> None:
    raise WireError(f"JSON: {name} is not allowed")


def _finite_float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise WireError(f"JSON: {text} is not a finite number")
    return v


def encode_json(obj: dict, version: int = VERSION) -> bytes:
    return json.dumps({"v": version, **obj}, separators=(",", ":"), allow_nan=False).encode()


def decode_json(buf: bytes, what: str = "message", versions: tuple[int, ...] = (VERSION,)) -> dict:
    if len(buf) > MAX_JSON_BYTES:
        raise WireError(f"{what}: {len(buf)} bytes, more than {MAX_JSON_BYTES}")
    try:
        obj = json.loads(bytes(buf).decode("utf-8"), parse_constant=_reject_constant, parse_float=_finite_float)
    except (ValueError, RecursionError) as e:  # incl. JSONDecodeError, bad UTF-8, 4300+ digit ints
        raise WireError(f"{what}: not JSON: {str(e)[:200]}") from None
    if not isinstance(obj, dict):
        raise WireError(f"{what}: expected a JSON object")
    if type(obj.get("v")) is not int or obj["v"] not in versions:
        raise WireError(
            f"{what}: protocol version {obj.get('v')!r}, this build speaks {' and '.join(map(str, versions))}"
        )
    return obj


def _field(obj: dict, name: str, types: Any, what: str, optional: bool = False) -> Any:
    if name not in obj:
        if optional:
            return None
        raise WireError(f"{what}: missing field {name!r}")
    v = obj[name]
    if v is None and optional:
        return None
    if isinstance(v, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise WireError(f"{what}: field {name!r} has the wrong type")
    if not isinstance(v, types):
        raise WireError(f"{what}: field {name!r} has the wrong type")
    return v


def decode_status(buf: bytes) -> dict:
    """An agent's status; checks the fields that other agents and the CLI rely on."""
    obj = decode_json(buf, "status")
    _field(obj, "id", int, "status")
    _field(obj, "role", str, "status")
    for name, v in obj.items():  # an agent's own words, shown in terminals (`swarm agents`, `kill`)
        if isinstance(v, str):
            obj[name] = printable(v, HOST_CHARS if name == "host" else TEXT_CHARS)
    _field(obj, "out", int, "status", optional=True)
    _field(obj, "hops", int, "status", optional=True)
    _field(obj, "rooted", bool, "status")
    for name in STATUS_COUNTERS:  # counters: absent in older agents
        v = _field(obj, name, int, "status", optional=True)
        if v is not None and v < 0:
            raise WireError(f"status: negative {name}")
    return obj


def decode_join_request(buf: bytes) -> dict:
    obj = decode_json(buf, "join request")
    if not 0 <= _field(obj, "id", int, "join request") <= MAX_AGENT_ID:
        raise WireError(f"join request: agent id {obj['id']} out of 0..{MAX_AGENT_ID}")
    _field(obj, "pid", int, "join request")
    obj["host"] = printable(_field(obj, "host", str, "join request"), HOST_CHARS)  # into events and info
    _field(obj, "spec", dict, "join request", optional=True)
    return obj


# --- every cold-path message: one encode/decode pair each ----------------------------------
# Nothing outside this module builds or checks these payloads (docs/reference/protocol.md#json).


def encode_join_request(agent: int, pid: int, host: str, spec: dict | None = None) -> bytes:
    """agent -> agent/<id>/join (the world's queryable): claim `agent` (a new agent brings
    its scenario spec). The id in the key and in the request must be the same."""
    return encode_json({"id": agent, "pid": pid, "host": host, **({"spec": spec} if spec is not None else {})})


def encode_join_reply(ok: bool, *, error: str | None = None, own_laws: bool = False, **fields: Any) -> bytes:
    """world -> agent: ok with run, agent, tick, key, clock, pose, brain; or an error.
    `own_laws`: the brain's "law" names other than the built-in laws: version 2
    (JOIN_REPLY_LAW_VERSION), so that only an agent that reads "law" accepts it."""
    if not ok:
        return encode_json({"ok": False, "error": error})
    return encode_json({"ok": True, **fields}, JOIN_REPLY_LAW_VERSION if own_laws else VERSION)


def decode_join_reply(buf: bytes) -> dict:
    """The world's answer to a claim; WireError unless it is a refusal with an error or an
    acceptance with a valid claim key and a brain configuration (checked by BrainConf)."""
    obj = decode_json(buf, "join reply", (VERSION, JOIN_REPLY_LAW_VERSION))
    if _field(obj, "ok", bool, "join reply") is False:
        _field(obj, "error", str, "join reply")
        return obj
    key = _field(obj, "key", int, "join reply")
    if not 0 <= key < 2**64:
        raise WireError("join reply: claim key out of range")
    _field(obj, "brain", dict, "join reply")
    return obj


def encode_status(status: dict) -> bytes:
    """agent -> agent/<id>/status (published and answered to queries)."""
    return encode_json(status)


def encode_info(info: dict) -> bytes:
    """world -> world/info query: the run and every agent (docs/reference/protocol.md#info)."""
    return encode_json(info)


def decode_info(buf: bytes) -> dict:
    obj = decode_json(buf, "world info")
    _field(obj, "run", str, "world info")
    _field(obj, "tick", int, "world info")
    _field(obj, "agents", dict, "world info")
    return obj


ADMIN_CMDS = ("pause", "resume", "stop")  # on world/admin (the operator)
SUPERVISE_CMDS = ("fault_done", "agent_exit")  # on world/supervise (the launcher alone)
EXIT_LOG_LINES, EXIT_LINE_CHARS = 20, 500  # agent_exit: at most this much of the agent's log


def encode_admin(cmd: str, **fields: Any) -> bytes:
    """operator -> world/admin query: pause, resume, stop (with `by`); launcher -> world/supervise
    query: fault_done (with `index`), agent_exit (see `encode_agent_exit`)."""
    return encode_json({"cmd": cmd, **fields})


def encode_agent_exit(agent: int, pid: int, code: int, crash: bool, cause: str, log: list[str]) -> bytes:
    """launcher -> world/supervise query: an agent process it started exited by itself.
    code: its exit status (negative: killed by that signal); crash: a failure of the agent
    (not the end of the run, a scripted fault or a signal from outside); cause: one line;
    log: the last lines of its output (trimmed to EXIT_LOG_LINES of EXIT_LINE_CHARS)."""
    return encode_admin(
        "agent_exit",
        id=agent,
        pid=pid,
        code=code,
        crash=crash,
        cause=cause[:EXIT_LINE_CHARS],
        log=[line[:EXIT_LINE_CHARS] for line in log[-EXIT_LOG_LINES:]],
    )


def decode_admin(buf: bytes, cmds: tuple[str, ...] = ADMIN_CMDS + SUPERVISE_CMDS) -> dict:
    """An admin or supervise request; WireError unless its cmd is one of `cmds` (the world
    passes those of the key it came on)."""
    obj = decode_json(buf, "admin request")
    cmd = obj.get("cmd")
    if cmd not in cmds:
        raise WireError(f"admin request: unknown cmd {printable(cmd, 40)!r} ({', '.join(cmds)})")
    if cmd in ADMIN_CMDS:  # who asked: free text, into the record and terminals (freetext.py)
        by = _field(obj, "by", str, f"admin request: {cmd}", optional=True)
        obj["by"] = "a client" if by is None else printable(by, BY_CHARS)
    if cmd == "fault_done":
        _field(obj, "index", int, "admin request: fault_done")
    elif cmd == "agent_exit":
        what = "admin request: agent_exit"
        if not 0 <= _field(obj, "id", int, what) <= MAX_AGENT_ID:
            raise WireError(f"{what}: agent id {obj['id']} out of 0..{MAX_AGENT_ID}")
        _field(obj, "pid", int, what)
        if not -255 <= _field(obj, "code", int, what) <= 255:
            raise WireError(f"{what}: exit code {obj['code']} out of -255..255")
        _field(obj, "crash", bool, what)
        if len(_field(obj, "cause", str, what)) > EXIT_LINE_CHARS:
            raise WireError(f"{what}: cause longer than {EXIT_LINE_CHARS} characters")
        log = _field(obj, "log", list, what)
        if len(log) > EXIT_LOG_LINES or any(type(x) is not str or len(x) > EXIT_LINE_CHARS for x in log):
            raise WireError(f"{what}: log must be at most {EXIT_LOG_LINES} strings of {EXIT_LINE_CHARS} characters")
        obj["cause"] = printable(obj["cause"], EXIT_LINE_CHARS)  # an agent's own words: escaped
        obj["log"] = [printable(x, EXIT_LINE_CHARS, keep="\t") for x in log]
    return obj


def encode_admin_reply(ok: bool, *, error: str | None = None, **fields: Any) -> bytes:
    return encode_json({"ok": True, **fields} if ok else {"ok": False, "error": error})


def decode_admin_reply(buf: bytes) -> dict:
    obj = decode_json(buf, "admin reply")
    _field(obj, "ok", bool, "admin reply")
    return obj


CTL_SIGNALS = ("KILL", "TERM", "STOP")


def encode_ctl(signal_name: str) -> bytes:
    """operator -> agent/<id>/ctl: take this signal (for agents on hosts one cannot signal)."""
    return encode_json({"kind": "signal", "signal": signal_name})


def decode_ctl(buf: bytes) -> str:
    obj = decode_json(buf, "ctl")
    if obj.get("kind") != "signal" or obj.get("signal") not in CTL_SIGNALS:
        raise WireError(f"ctl: expected kind 'signal' and a signal in {CTL_SIGNALS}")
    return obj["signal"]


PROCESS_FAULT_KINDS = ("kill", "restart", "freeze", "thaw")


@dataclass(frozen=True, slots=True)
class FaultNotice:
    """world -> world/control: carry out scripted process fault `index` at `tick`."""

    index: int
    tick: int
    kind: str  # kill | restart | freeze | thaw
    agent: int
    fault: dict  # the whole fault, as in the summary


def encode_end(tick: int) -> bytes:
    """world -> world/control: the run is over."""
    return encode_json({"kind": "end", "tick": tick})


def encode_fault_notice(index: int, tick: int, fault: dict) -> bytes:
    return encode_json({"kind": "fault", "index": index, "tick": tick, "fault": fault})


def decode_control(buf: bytes) -> int | FaultNotice:
    """A control notice: the end (its tick, an int) or a FaultNotice; WireError otherwise."""
    obj = decode_json(buf, "control")
    kind = obj.get("kind")
    if kind == "end":
        return _field(obj, "tick", int, "control: end")
    if kind != "fault":
        raise WireError(f"control: unknown kind {kind!r}")
    index = _field(obj, "index", int, "control: fault")
    tick = _field(obj, "tick", int, "control: fault", optional=True)
    f = _field(obj, "fault", dict, "control: fault")
    agent, fkind = f.get("agent"), f.get("kind")
    if type(agent) is not int or fkind not in PROCESS_FAULT_KINDS:
        raise WireError("control: fault: needs an integer agent and a kind in " + ", ".join(PROCESS_FAULT_KINDS))
    return FaultNotice(index, -1 if tick is None else tick, fkind, agent, f)


def encode_event(event: dict, seq: int = 0) -> bytes:
    """world -> events: one event of the run (as in summary.json), with its sequence number
    (`next_seq`; 0: not numbered) beside it, not in it."""
    return encode_json({"event": event, **({"seq": seq} if seq else {})})


def decode_event(buf: bytes) -> dict:
    return decode_event_numbered(buf)[0]


def decode_event_numbered(buf: bytes) -> tuple[dict, int]:
    """(the event, its sequence number: 0 when not numbered)."""
    obj = decode_json(buf, "event")
    ev = _field(obj, "event", dict, "event")
    _field(ev, "kind", str, "event")
    seq = _field(obj, "seq", int, "event", optional=True) or 0
    if not 0 <= seq < SEQ_MOD:
        raise WireError(f"event: sequence number {seq} out of 0..{SEQ_MOD - 1}")
    return ev, seq
