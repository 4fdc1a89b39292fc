"""A run's recording: every tick of ground truth, and the result files made from it.

A run with an output directory streams its ticks to recording.mcap as it goes
(`StreamRecorder`, world/stream.py); one without (studies, tests) keeps them in memory
(`Recorder`). At the end, or after a crash (`recover_run`), trajectory.npz and
summary.json are written from the recording, by streaming it (world/results_stream.py:
memory does not grow with the run's length), each to a temporary name and renamed, so a
result file is either whole or absent. The layout is documented in docs/reference/outputs.md
(#summary, #trajectory); the reader of trajectory.npz is world/run_reader.py.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.world.metrics import agent_metrics, converged, recovery, relative_errors, switch_ticks
from swarm.world.results_stream import (
    PER_TICK,
    Metrics,
    Scan,
    follow_counts,
    scan,
    state_seconds,
    streamed,
    write_npz,
)
from swarm.world.stream import RECORDING_FILE, Recording, RecordingError, StreamWriter

TRAJECTORY_FILE = "trajectory.npz"
SUMMARY_FILE = "summary.json"
RESULT_FILES = (RECORDING_FILE, TRAJECTORY_FILE, SUMMARY_FILE)
__all__ = [
    "RECORDING_FILE",
    "RESULT_FILES",
    "RecordingError",
    "Recorder",
    "StreamRecorder",
    "RunResult",
    "recover_run",
    "write_run",
]


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
    reads it back."""

    def __init__(self, scenario: Scenario, ticks: int, path: Path):
        self.scenario = scenario
        self.ticks = ticks
        self.path = path
        self.rows = 0
        self.ids = np.array(scenario.ids, dtype=np.int64)
        self.t_last = 0.0
        self.writer = StreamWriter(path, scenario, ticks)
        self._arrays: dict[str, np.ndarray] | None = None

    def add_agent(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.ids = np.array(scenario.ids, dtype=np.int64)
        self.writer.add_agent(scenario.agents[-1], self.t_last)

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

    def arrays(self) -> dict[str, np.ndarray]:
        if self._arrays is None:
            self._arrays = streamed_arrays(self.finished())
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


class _Loaded:
    """Arrays already read (a recovered run), in the recorder's place."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        self._arrays = arrays

    def arrays(self) -> dict[str, np.ndarray]:
        return self._arrays


@dataclass
class RunResult:
    scenario: Scenario
    recorder: HasArrays
    events: list[dict] = field(default_factory=list)
    extra: dict = field(default_factory=dict)  # engine-specific figures for summary.json
    agent_extra: dict = field(default_factory=dict)  # str(id) -> engine figures per agent

    def summary(self) -> dict:
        a = self.recorder.arrays()
        if len(a["t"]) == 0:
            agents: dict = {}
            switches = 0
        else:
            counts = [len(k) for k in switch_ticks(a["out"], a["alive"])]
            switches = sum(counts)
            agents = agent_metrics(
                ids=a["ids"],
                roles=a["role"],
                speeds=a["speed"],
                orbit_radius=a["orbit_radius"],
                t=a["t"],
                x=a["x"],
                y=a["y"],
                alive=a["alive"],
                out_final=a["out"][-1],
                target=a["target"],
                switches=counts,
            )
            add_state_seconds(agents, a, self.scenario.run.dt)
        faults = []
        if self.scenario.faults and len(a["t"]) > 1:
            err = relative_errors(
                ids=a["ids"],
                roles=a["role"],
                speeds=a["speed"],
                orbit_radius=a["orbit_radius"],
                x=a["x"],
                y=a["y"],
                alive=a["alive"],
                out=a["out"],
                target=a["target"],
            )
            specs = [
                {"index": i, **{k: v for k, v in f.model_dump().items() if v is not None}}
                for i, f in enumerate(self.scenario.faults)
            ]
            faults = recovery(specs, a["t"], err, a["missed"], self.events)
        sim_time = float(a["t"][-1]) if len(a["t"]) else 0.0
        return self.summary_of(len(a["t"]), agents, switches, faults, sim_time)

    def summary_of(self, rows: int, agents: dict, switches: int, faults: list, sim_time: float) -> dict:
        """summary.json from the run's figures (computed from whole arrays by `summary`, or
        streamed by `write_run`)."""
        for aid, more in self.agent_extra.items():
            if aid in agents:
                agents[aid].update(more)
        return {
            "scenario": self.scenario.name,
            # An agent process that crashed (not a scripted kill: that is a "fault") fails the run.
            "converged": converged(agents) and not any(e["kind"] == EventKind.CRASH for e in self.events),
            "ticks": max(rows - 1, 0),
            "selection": self.scenario.sensing.selection,
            "switches": switches,
            "sim_time": sim_time,
            "dt": self.scenario.run.dt,
            "agents": agents,
            "events": self.events,
            "faults": faults,
            # False: rebuilt from the recording of a run whose world died, or a recording
            # that could not be written to the end (disk full)
            "complete": not getattr(self.recorder, "torn", False),
            **self.extra,
        }


def add_state_seconds(agents: dict, a: dict[str, np.ndarray], dt: float) -> None:
    """Each follower's `state_s` (results_stream.state_seconds) into summary.json's `agents`,
    from whole arrays; a recording without `follow` (older runs) says none throughout."""
    follow = a.get("follow")
    if follow is None:
        follow = np.zeros(a["alive"].shape, dtype=np.int8)
    counts = follow_counts(follow[:-1], a["alive"][:-1])
    for k, (i, role) in enumerate(zip(a["ids"].tolist(), a["role"].tolist())):
        if role == "follower" and str(i) in agents:
            agents[str(i)]["state_s"] = state_seconds(counts[k], dt)


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


def _write_atomic(path: Path, write: Any) -> None:
    """`write(f)` into a temporary file beside `path`, then rename: `path` is whole or absent.
    Raises RecordingError naming the file (disk full, file too large, ...)."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        tmp.replace(path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise RecordingError(f"cannot write {path}: {e.strerror or e}") from None


def _write_summary(summary: dict, out_dir: Path) -> dict:
    text = (json.dumps(summary, indent=2, default=_json_default) + "\n").encode()
    _write_atomic(out_dir / SUMMARY_FILE, lambda f: f.write(text))
    return summary


def write_run(result: RunResult, out_dir: Path) -> dict:
    """Write trajectory.npz and summary.json into out_dir (each atomically); returns the summary.
    A run recorded to recording.mcap (`StreamRecorder`) has them written by streaming the
    recording (world/results_stream.py): memory does not grow with the run's length."""
    out_dir.mkdir(parents=True, exist_ok=True)
    finished = getattr(result.recorder, "finished", None)
    if finished is not None:
        return _write_streamed(finished(), out_dir, result)
    arrays = result.recorder.arrays()
    _write_atomic(out_dir / TRAJECTORY_FILE, lambda f: np.savez_compressed(f, **arrays))  # type: ignore[arg-type]  # numpy's stubs: **kw could be allow_pickle
    return _write_summary(result.summary(), out_dir)


def _write_streamed(path: Path, out_dir: Path, result: RunResult, sc: Scan | None = None) -> dict:
    """`write_run` from the recording at `path`, read in passes: the arrays of trajectory.npz
    through .npy files in a temporary directory in `out_dir`, the summary's figures by
    streaming accumulators. The same files as `write_run` from `recording_arrays`, to the bit."""
    with streamed(path, out_dir, sc) as (sc, files):
        static = static_arrays(sc.scenario)
        m = Metrics(result.scenario, static, result.events)
        m.compute(files)
        _write_atomic(out_dir / TRAJECTORY_FILE, lambda f: write_npz(f, static, files))
    return _write_summary(result.summary_of(files.rows, m.agents, m.switches, m.faults, m.sim_time), out_dir)


def recover_run(run_dir: Path) -> dict:
    """Rebuild trajectory.npz and summary.json from what reached run_dir/recording.mcap (a
    world killed mid-run): every tick up to the last flush. The summary says
    `"complete": false`; figures only the world process knew (commands, missed ticks,
    wall time) are absent. Raises ValueError when there is no readable recording."""
    path = run_dir / RECORDING_FILE
    if not path.is_file():
        raise ValueError(f"{path}: no recording to recover from")
    sc = scan(path)
    if not sc.messages:
        raise ValueError(f"{path}: the recording holds no tick")
    result = RunResult(
        sc.scenario,
        _Loaded({}),  # nothing in memory: the results are streamed from the recording
        sc.events,
        {"engine": "recovered", "complete": False, "recording_finished": sc.complete, "completed": False},
    )
    return _write_streamed(path, run_dir, result, sc)
