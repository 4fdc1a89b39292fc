"""A run's recording as it goes: an MCAP file (`recording.mcap`) written tick by tick.

MCAP is the robotics ecosystem's log format (Foxglove, ROS 2 bags). The file is written
with foxglove-sdk and read back with the `mcap` package. Its channels:

- `/swarm/ticks`  every tick, exact: message encoding `swarm-tick-v2`, little-endian
  `int64 tick, float64 time, int64 n, int64 missed`, then `int64 ids[n]`, `float64 x[n],
  y[n], heading[n], u[n]`, `int64 out[n]` (-1: none), `uint8 alive[n]`, `int8 follow[n]`
  (follow state codes, wire.FOLLOW_STATES). trajectory.npz and summary.json are rebuilt
  from these rows. `swarm-tick-v1` (recordings before the follow states) is the same
  without `follow`: read as all none.
- `/swarm/scene`  foxglove.SceneUpdate at most 10 times per simulated second: agents as
  arrows (leaders red, followers blue), out-neighbour edges as lines, the target as a
  sphere, the expected orbits as circles; what Foxglove draws in its 3D panel.
- `/swarm/trails` foxglove.SceneUpdate, about once per 2.5 simulated s: each agent's path.
- `/swarm/agents` JSON with each scene update: per agent pose, turn rate u, out-neighbour,
  root, expected radius and radial error (to plot). The three: world/scene.py.
- `/swarm/events` JSON, one message per event (join, drop, switch, fault, ...).
- `/swarm/run`    JSON: first `{"scenario": ..., "ticks": ...}`, then `{"add_agent": spec}`
  for each agent added at run time, so that a recording is readable on its own.

`swarm up --foxglove` serves the same channels (but `/swarm/ticks`) live over Foxglove's
WebSocket protocol: world/live_view.py attaches a server to this writer's context.

Log times are simulated time in nanoseconds. A chunk is written every FLUSH_PERIOD s of
wall time (and only then: no size limit, so every write, and every write error, happens
in `flush`), so a writer killed with SIGKILL leaves a file that `read_recording` reads
up to its last flush: at most about a second is lost. Memory stays flat: nothing is
kept but the chunk being filled.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.contracts.scenario_tables import AgentSpec
from swarm.world.files import RECORDING_FILE as RECORDING_FILE
from swarm.world.files import RecordingError as RecordingError
from swarm.world.scene import SCENE_RATE, SceneChannels, log_time

TICK_ENCODING = "swarm-tick-v2"
TICK_BYTES_V1 = 6 * 8 + 1  # bytes per agent of a swarm-tick-v1 message (no follow states)
TICK_BYTES = TICK_BYTES_V1 + 1  # and of a swarm-tick-v2 one
FLUSH_PERIOD = 0.5  # s of wall time between flushes (a SIGKILL loses at most about this)
_HEAD = np.dtype([("tick", "<i8"), ("time", "<f8"), ("n", "<i8"), ("missed", "<i8")])


def encode_tick(
    tick: int,
    t: float,
    ids: Any,
    x: Any,
    y: Any,
    heading: Any,
    u: Any,
    out: Any,
    alive: Any,
    missed: int,
    follow: Any = None,
) -> bytes:
    """One swarm-tick-v2 message (follow None: all none)."""
    n = len(ids)
    head = np.array([(tick, t, n, missed)], dtype=_HEAD).tobytes()
    return b"".join(
        (
            head,
            np.asarray(ids, "<i8").tobytes(),
            np.asarray(x, "<f8").tobytes(),
            np.asarray(y, "<f8").tobytes(),
            np.asarray(heading, "<f8").tobytes(),
            np.asarray(u, "<f8").tobytes(),
            np.asarray(out, "<i8").tobytes(),
            np.asarray(alive, np.uint8).tobytes(),
            (np.zeros(n, np.int8) if follow is None else np.asarray(follow, np.int8)).tobytes(),
        )
    )


def tick_width(n: int, size: int) -> int:
    """Bytes per agent of a tick message of `size` bytes for n agents: TICK_BYTES (v2) or
    TICK_BYTES_V1 (v1); ValueError when it is neither."""
    if n >= 0:
        for width in (TICK_BYTES, TICK_BYTES_V1):
            if size == _HEAD.itemsize + n * width:
                return width
    raise ValueError(f"a {TICK_ENCODING} message of {size} bytes for {n} agents")


def decode_tick(data: bytes) -> dict:
    """A tick message (v2, or v1: follow all none)."""
    head = np.frombuffer(data, _HEAD, 1)[0]
    n = int(head["n"])
    width = tick_width(n, len(data))
    o = _HEAD.itemsize
    cols = {}
    for name, dt in (("ids", "<i8"), ("x", "<f8"), ("y", "<f8"), ("heading", "<f8"), ("u", "<f8"), ("out", "<i8")):
        cols[name] = np.frombuffer(data, dt, n, o)
        o += 8 * n
    cols["alive"] = np.frombuffer(data, np.uint8, n, o).astype(bool)
    o += n
    cols["follow"] = np.frombuffer(data, np.int8, n, o) if width == TICK_BYTES else np.zeros(n, np.int8)
    return {"tick": int(head["tick"]), "time": float(head["time"]), "missed": int(head["missed"]), **cols}


class StreamWriter:
    """Writes one run's recording.mcap; `close()` finishes the file."""

    def __init__(self, path: Path, scenario: Scenario, ticks: int):
        # lazy: foxglove (18 ms) only to write a recording; readers of a run (plots, results) import this module
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.path = path
        self.ctx = foxglove.Context()  # one per recording: runs in one process never mix
        try:
            self.writer = foxglove.open_mcap(
                str(path),
                allow_overwrite=True,
                context=self.ctx,
                writer_options=MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=None),
            )
        except Exception as e:
            raise RecordingError(f"cannot write {path}: {e}") from None
        schema = foxglove.Schema(name="swarm.Tick", encoding="", data=b"")
        self.ticks_ch = foxglove.Channel(
            "/swarm/ticks", schema=schema, message_encoding=TICK_ENCODING, context=self.ctx
        )
        self.scene_every = max(1, int(round(1.0 / (SCENE_RATE * scenario.run.dt))))
        self.channels = SceneChannels(
            self.ctx,
            (scenario.target.x, scenario.target.y),
            scenario.agents,
            1.0 / (self.scene_every * scenario.run.dt),
        )
        self.last_flush = time.monotonic()
        self.closed = False
        self.failed = False  # a write failed: the file ends at the last good flush
        self.channels.run({"scenario": scenario.model_dump(mode="json"), "ticks": ticks})

    def add_agent(self, spec: AgentSpec, t: float) -> None:
        self.channels.add_agent(spec, spec.model_dump(mode="json"), t)

    def event(self, ev: dict) -> None:
        self.channels.event(ev)

    def tick(
        self,
        tick: int,
        t: float,
        ids: Any,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        missed: int,
        follow: Any = None,
    ) -> None:
        self.ticks_ch.log(encode_tick(tick, t, ids, x, y, heading, u, out, alive, missed, follow), log_time=log_time(t))
        if tick % self.scene_every == 0:
            self.channels.tick(tick, t, ids, x, y, heading, u, out, alive, follow)
        now = time.monotonic()
        if now - self.last_flush >= FLUSH_PERIOD:
            self.flush()

    def flush(self) -> None:
        self.last_flush = time.monotonic()
        try:
            self.writer.flush()
        except Exception:  # foxglove reports an I/O error as RuntimeError
            self._failed()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            self.writer.close()
        except Exception:
            self._failed()

    def _failed(self) -> None:
        """A write failed (disk full, file too large): what was flushed before stays readable.
        The writer is closed now, so that it has nothing left to say when it is dropped."""
        self.closed = self.failed = True
        try:
            self.writer.close()
        except Exception:
            pass
        raise RecordingError(f"cannot write {self.path}: I/O error (disk full or file too large?)")


@dataclass
class Recording:
    """What `read_recording` found: the scenario (with agents added at run time), the tick
    rows in order, the events, and whether the file was finished (False: its writer died)."""

    scenario: Scenario
    ticks: int
    rows: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    complete: bool = False


def _records(f: Any) -> Iterator[Any]:
    """The MCAP records of `f` up to its end, or up to where it is torn (a writer killed
    mid-chunk): whatever the reader raises there (a short read, a bad length, a truncated
    compressed chunk) ends the file. The second value says whether the footer was reached."""
    # lazy: mcap (zstandard) only to read a recording back; the world that writes one never does
    from mcap.records import Footer
    from mcap.stream_reader import StreamReader

    records = iter(StreamReader(f, skip_magic=False).records)
    while True:
        try:
            r = next(records)
        except StopIteration:
            return
        except Exception:  # the torn tail of a file whose writer died
            return
        yield r, isinstance(r, Footer)


def read_recording(path: Path, on_tick: Callable[[bytes], None] | None = None, events: bool = True) -> Recording:
    """Read a recording.mcap, finished or cut short (a torn tail is where it stops).
    Raises ValueError when the file is not a swarm recording at all.

    `on_tick`: each tick message's bytes (after the run header) go to it, in the file's order,
    instead of into `Recording.rows`, which stays empty: a reader that streams the ticks
    (world/results_stream.py) keeps nothing per tick. `events=False`: the events are not read
    (`Recording.events` stays empty)."""
    from mcap.records import Channel, Message  # lazy: as in _records

    topics: dict[int, str] = {}
    rec: Recording | None = None
    added: list[dict] = []
    with open(path, "rb") as f:
        for r, footer in _records(f):
            if isinstance(r, Channel):
                topics[r.id] = r.topic
            elif isinstance(r, Message):
                topic = topics.get(r.channel_id)
                if topic == "/swarm/ticks" and rec is not None:
                    if on_tick is None:
                        rec.rows.append(decode_tick(r.data))
                    else:
                        on_tick(r.data)
                elif topic == "/swarm/events" and rec is not None and events:
                    rec.events.append(json.loads(r.data))
                elif topic == "/swarm/run":
                    msg = json.loads(r.data)
                    if "scenario" in msg:
                        # read back, its laws are names: nothing is imported
                        scen = Scenario.model_validate(msg["scenario"], context={"check_laws": False})
                        rec = Recording(scen, int(msg["ticks"]))
                    elif "add_agent" in msg:
                        added.append(msg["add_agent"])
            elif footer and rec is not None:
                rec.complete = True
    if rec is None:
        raise ValueError(f"{path}: not a swarm recording (no /swarm/run header)")
    if added:  # as the world added them: each spec checked, not the scenario's cross-agent rules again
        rec.scenario = rec.scenario.model_copy(
            update={"agents": [*rec.scenario.agents, *(AgentSpec.model_validate(a) for a in added)]}
        )
    return rec
