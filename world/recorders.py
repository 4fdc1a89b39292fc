"""How a run's ticks are recorded, and the arrays of trajectory.npz made from a recording.

The recorders the engine records into (`TickRecorder`): in memory (`Recorder`, studies and
tests), streamed to recording.mcap as the run goes (`StreamRecorder`, world/stream.py), or
deferred by one tick (`DeferredRecorder`); the arrays from a recording, by streaming
(`streamed_arrays`, world/results_stream.py) or all in memory (`recording_arrays`). Writing
the run directory from them: world/recording.py, which re-exports these names.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.world.results_stream import PER_TICK, streamed
from swarm.world.stream import Recording, StreamWriter


def static_arrays(s: Scenario) -> dict[str, np.ndarray]:
    """The per-agent and per-run constants of trajectory.npz."""
    return {
        "ids": np.array(s.ids, dtype=np.int64),
        "role": np.array([a.role for a in s.agents]),
        "speed": np.array([a.speed for a in s.agents], dtype=float),
        "orbit_radius": np.array([a.orbit_radius if a.orbit_radius else math.nan for a in s.agents]),
        "target": np.array([s.target.x, s.target.y], dtype=float),
        "dt": np.array(s.run.dt),
    }


class TickRecorder(Protocol):
    """What the engine records a run into (world/engine.py): `Recorder`, `StreamRecorder`,
    `DeferredRecorder`."""

    @property
    def rows(self) -> int:
        """Ticks recorded (the last one + 1)."""
        ...

    def record(
        self,
        tick: int,
        time: float,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        missed: int = 0,
        follow: Any = None,
    ) -> None: ...

    def event(self, ev: dict) -> None: ...

    def add_agent(self, scenario: Scenario) -> None: ...

    def arrays(self) -> dict[str, np.ndarray]: ...


class HasArrays(Protocol):
    """What a run's results are computed from (`RunResult`): the arrays of trajectory.npz."""

    def arrays(self) -> dict[str, np.ndarray]: ...


class Recorder:
    """Preallocated per-tick arrays; row k is the state at tick k (rows 0..ticks)."""

    def __init__(self, scenario: Scenario, ticks: int):
        n = len(scenario.agents)
        self.scenario = scenario
        self.ticks = ticks
        self.rows = 0
        self.t = np.full(ticks + 1, np.nan)
        self.x = np.full((ticks + 1, n), np.nan)
        self.y = np.full((ticks + 1, n), np.nan)
        self.heading = np.full((ticks + 1, n), np.nan)
        self.u = np.full((ticks + 1, n), np.nan)
        self.out = np.full((ticks + 1, n), -1, dtype=np.int64)
        self.alive = np.zeros((ticks + 1, n), dtype=bool)
        self.missed = np.zeros(ticks + 1, dtype=np.int64)  # live agents whose command was held
        self.follow = np.zeros((ticks + 1, n), dtype=np.int8)  # follow state codes (wire.FOLLOW_STATES)

    def add_agent(self, scenario: Scenario) -> None:
        """One more column (an agent added at run time); earlier rows say it was absent."""
        self.scenario = scenario
        rows = self.t.shape[0]
        grow = lambda a, fill: np.concatenate([a, np.full((rows, 1), fill, dtype=a.dtype)], axis=1)  # noqa: E731
        self.x, self.y, self.heading, self.u = (grow(a, np.nan) for a in (self.x, self.y, self.heading, self.u))
        self.out = grow(self.out, -1)
        self.alive = grow(self.alive, False)
        self.follow = grow(self.follow, 0)

    def record(
        self,
        tick: int,
        time: float,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        missed: int = 0,
        follow: Any = None,
    ) -> None:
        """Store tick `tick`: pose at t_k and the turn rate applied over [t_k, t_k+1); follow:
        the agents' follow state codes (None: all none)."""
        self.t[tick] = time
        self.x[tick] = x
        self.y[tick] = y
        self.heading[tick] = heading
        self.u[tick] = u
        self.out[tick] = out
        self.alive[tick] = alive
        self.missed[tick] = missed
        self.follow[tick] = 0 if follow is None else follow
        self.rows = max(self.rows, tick + 1)

    def event(self, ev: dict) -> None:
        """Events are kept by the engine; a memory recording has nothing more to do."""

    def arrays(self) -> dict[str, np.ndarray]:
        n = self.rows
        return {
            **static_arrays(self.scenario),
            "t": self.t[:n],
            "x": self.x[:n],
            "y": self.y[:n],
            "heading": self.heading[:n],
            "u": self.u[:n],
            "out": self.out[:n],
            "alive": self.alive[:n],
            "missed": self.missed[:n],
            "follow": self.follow[:n],
        }


class StreamRecorder:
    """The recorder of a run with an output directory: each tick goes to recording.mcap
    as it is recorded (world/stream.py) and nothing stays in memory, so memory is flat
    however long the run and however many agents join. `arrays()` finishes the file and
    reads it back.

    `keep`: the ticks are also kept in memory (a `Recorder`, `memory`), for a shell that
    returns the arrays anyway (`swarm sim`, `swarm.simulate`) or a run small enough (the
    world process, `keep_max`): `arrays()` and `write_run` then use them instead of reading
    the recording back (the same arrays and files, to the bit: tests/pure/test_results_stream.py).
    `keep_max`: agent-ticks ((ticks + 1) x agents) kept at most; a run larger than that from
    the start, or once agents added at run time make it so, keeps nothing (memory flat: the
    results are streamed from the recording)."""

    def __init__(self, scenario: Scenario, ticks: int, path: Path, keep: bool = False, keep_max: int | None = None):
        self.scenario = scenario
        self.ticks = ticks
        self.path = path
        self.rows = 0
        self.ids = np.array(scenario.ids, dtype=np.int64)
        self.t_last = 0.0
        self.writer = StreamWriter(path, scenario, ticks)
        self._arrays: dict[str, np.ndarray] | None = None
        self.keep_max = keep_max
        self.memory = Recorder(scenario, ticks) if keep and self._fits(len(scenario.agents)) else None

    def _fits(self, agents: int) -> bool:
        """Whether `agents` columns of (ticks + 1) rows may be kept in memory (`keep_max`)."""
        return self.keep_max is None or (self.ticks + 1) * agents <= self.keep_max

    def add_agent(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.ids = np.array(scenario.ids, dtype=np.int64)
        self.writer.add_agent(scenario.agents[-1], self.t_last)
        if self.memory is not None:
            if self._fits(len(scenario.agents)):
                self.memory.add_agent(scenario)
            else:  # too large to keep now: the results are read back from the recording
                self.memory = None

    def event(self, ev: dict) -> None:
        self.writer.event(ev)

    def record(
        self,
        tick: int,
        time: float,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        missed: int = 0,
        follow: Any = None,
    ) -> None:
        self.writer.tick(tick, time, self.ids, x, y, heading, u, out, alive, missed, follow)
        if self.memory is not None:
            self.memory.record(tick, time, x, y, heading, u, out, alive, missed, follow)
        self.t_last = time
        self.rows = max(self.rows, tick + 1)

    def close(self) -> None:
        self.writer.close()

    @property
    def torn(self) -> bool:
        """The recording could not be written to the end: it stops at its last good flush."""
        return self.writer.failed

    def finished(self) -> Path:
        """The recording, finished (its writer closed): what `write_run` streams the results from."""
        self.writer.close()
        return self.path

    def kept(self) -> Recorder | None:
        """The ticks kept in memory (`keep`), once the recording is finished and whole; None
        otherwise (not kept, or the file stops at its last good flush: read it back)."""
        if self.memory is None:
            return None
        self.finished()
        return None if self.torn else self.memory

    def arrays(self) -> dict[str, np.ndarray]:
        if self._arrays is None:
            kept = self.kept()
            if kept is None:
                self._arrays = streamed_arrays(self.finished())
            else:  # in the order of streamed_arrays (trajectory.npz's members)
                a = kept.arrays()
                self._arrays = {**static_arrays(kept.scenario), **{k: a[k] for k in PER_TICK}}
        return self._arrays


class DeferredRecorder:
    """A recorder whose ticks are written one step late: `record` keeps the tick (copies of
    its arrays), `flush` writes it. The world flushes right after it has sent the next tick's
    frames, so writing the recording overlaps the agents' turn instead of delaying the next
    tick. Everything else (an event, a new agent, reading `rows`, closing) flushes first, so
    what is written, and in what order, is the same as with the recorder it wraps."""

    def __init__(self, inner: TickRecorder):
        self.inner = inner
        self.pending: tuple | None = None

    def record(
        self,
        tick: int,
        time: float,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        missed: int = 0,
        follow: Any = None,
    ) -> None:
        self.flush()
        self.pending = (
            tick,
            time,
            np.array(x),
            np.array(y),
            np.array(heading),
            np.array(u),
            np.array(out),
            np.array(alive),
            missed,
            None if follow is None else np.array(follow),
        )

    def flush(self) -> None:
        if self.pending is not None:  # written, then forgotten: a signal in between (the world's
            self.inner.record(*self.pending)  # Stop) leaves it pending, written again at worst,
            self.pending = None  # and a tick written twice counts once

    @property
    def rows(self) -> int:
        self.flush()
        return self.inner.rows

    def event(self, ev: dict) -> None:
        self.flush()
        self.inner.event(ev)

    def add_agent(self, scenario: Scenario) -> None:
        self.flush()
        self.inner.add_agent(scenario)

    def arrays(self) -> dict[str, np.ndarray]:
        self.flush()
        return self.inner.arrays()

    def __getattr__(self, name: str) -> Any:  # the wrapped recorder's own (path, writer, close, torn)
        self.flush()
        return getattr(self.inner, name)


def streamed_arrays(path: Path) -> dict[str, np.ndarray]:
    """`recording_arrays(read_recording(path))`, without a dict per tick: the arrays are
    decoded in batches (world/results_stream.py) through files beside the recording."""
    with streamed(path, path.parent) as (sc, files):
        return {**static_arrays(sc.scenario), **{k: np.load(files.path(k)) for k in PER_TICK}}


def recording_arrays(rec: Recording) -> dict[str, np.ndarray]:
    """The arrays of trajectory.npz from a recording's tick rows (agents added at run time
    are columns of their own, absent before they were added). A tick written twice (a
    signal between writing a row and counting it, then the final row) counts once, the
    later; rows stop at the first missing tick. All in memory: the results of a run are
    written by streaming instead (`write_run`, world/results_stream.py), to the same arrays."""
    s = rec.scenario
    col = {aid: j for j, aid in enumerate(s.ids)}
    by_tick = {row["tick"]: row for row in rec.rows}
    rows = 0
    while rows in by_tick:
        rows += 1
    n = len(col)
    a = {"t": np.full(rows, np.nan), "missed": np.zeros(rows, dtype=np.int64)}
    for key in ("x", "y", "heading", "u"):
        a[key] = np.full((rows, n), np.nan)
    a["out"] = np.full((rows, n), -1, dtype=np.int64)
    a["alive"] = np.zeros((rows, n), dtype=bool)
    a["follow"] = np.zeros((rows, n), dtype=np.int8)
    for r in range(rows):
        row = by_tick[r]
        a["t"][r], a["missed"][r] = row["time"], row["missed"]
        m = len(row["ids"])
        if m <= n and all(col.get(int(i)) == j for j, i in enumerate(row["ids"])):
            cols: slice | list[int] = slice(0, m)  # the usual case: the scenario's order
        else:
            cols = [col[int(i)] for i in row["ids"]]
        for key in ("x", "y", "heading", "u", "out", "alive", "follow"):
            a[key][r, cols] = row[key]
    return {**static_arrays(s), **a}
