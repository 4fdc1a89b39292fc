"""A run's recording: every tick of ground truth, and the result files made from it.

A run with an output directory streams its ticks to recording.mcap as it goes
(`StreamRecorder`, world/stream.py); one without (studies, tests) keeps them in memory
(`Recorder`; the recorders: world/recorders.py, re-exported here). At the end, or after a
crash (`recover_run`), trajectory.npz and summary.json are written from the recording, by
streaming it (world/results_stream.py: memory does not grow with the run's length), each to
a temporary name and renamed, so a result file is either whole or absent. The layout is
documented in docs/reference/outputs.md (#summary, #trajectory); the reader of
trajectory.npz is world/run_reader.py.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.world.files import RECORDING_FILE, RESULT_FILES, SUMMARY_FILE, TRAJECTORY_FILE
from swarm.world.metrics import agent_metrics, converged, recovery, relative_errors, switch_ticks
from swarm.world.recorders import DeferredRecorder as DeferredRecorder
from swarm.world.recorders import HasArrays, Recorder, StreamRecorder, static_arrays
from swarm.world.recorders import TickRecorder as TickRecorder
from swarm.world.recorders import recording_arrays as recording_arrays
from swarm.world.recorders import streamed_arrays as streamed_arrays
from swarm.world.results_metrics import Metrics, follow_counts, state_seconds
from swarm.world.results_stream import Scan, scan, streamed, write_npz
from swarm.world.stream import RecordingError

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
    """Each follower's `state_s` (results_metrics.state_seconds) into summary.json's `agents`,
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
    recording (world/results_stream.py): memory does not grow with the run's length; unless
    its ticks were also kept in memory (`StreamRecorder(keep=True)`: `swarm sim`), then they
    are written from those, as a run without a recording (the same files, to the bit)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    kept = getattr(result.recorder, "kept", None)
    memory = None if kept is None else kept()  # the ticks also kept in memory (`swarm sim`)
    finished = getattr(result.recorder, "finished", None)
    if finished is not None and memory is None:
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
