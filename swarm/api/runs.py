"""The Python API: what a notebook needs, from `import swarm` (swarm/__init__.py exports
these names lazily, so the agent processes, which import swarm.contracts, pay nothing).

- Scenarios (swarm/api/scenario.py): `load(path)`, `from_dict(data)`, `Builder`; bad
  ones raise `ScenarioError` with the messages `swarm check` prints.
- `simulate(scenario, duration=None, out=None)`: `swarm sim`'s engine in this process
  (swarm/offline/sim.py; `batch=True`: swarm/offline/batch.py's), the same results to the bit; with
  `out`, the same run directory as `swarm sim --out` (recording, trajectory, summary).
- `open_run(dir)`: a finished run directory of `swarm sim` or `swarm up` (rebuilt from
  its recording first if its world died, as `swarm plot` does; `Results.recovered` says
  what was rebuilt).
- `Results`: trajectory.npz's arrays as attributes (`t` (T,), `x`, `y`, `heading`, `u`,
  `out`, `alive` (T, N) in the order of `ids`; `agent(id)` for one agent's columns), the
  summary as a `Summary` (attribute access: `summary.converged`,
  `summary.agents[3].radial_error`), `plot()` (swarm/plots, into a run directory),
  `write_csv()` (`swarm export --csv`'s files).
- `up(...)`: the distributed runtime, as a handle (swarm/api/up.py); `launch(...)`: the
  same, run in this process until it ends (swarm/api/launch.py, what `swarm up` calls).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarm.api.record import Record, Summary
from swarm.api.scenario import Builder, Scenario, ScenarioError, as_scenario, source_of, with_duration
from swarm.offline.csv_export import write_agent_csvs
from swarm.offline.results import OutDirError, Recovery, claim_out_dir
from swarm.offline.results import recover as rebuild
from swarm.world.recording import RECORDING_FILE, SUMMARY_FILE, TRAJECTORY_FILE, RunResult, write_run
from swarm.world.run_reader import RunReadError, load_run

__all__ = ["AgentTrack", "Record", "Results", "RunReadError", "Summary", "open_run", "simulate"]

#: Per-tick arrays of trajectory.npz (docs/reference/outputs.md#trajectory).
TICK_ARRAYS = ("t", "x", "y", "heading", "u", "out", "alive", "missed", "follow")
#: Per-agent and per-run constants.
STATIC_ARRAYS = ("ids", "role", "speed", "orbit_radius", "target", "dt")


@dataclass(frozen=True)
class AgentTrack:
    """One agent's columns of a run: (T,) arrays, and its summary entry (None if absent)."""

    id: int
    role: str
    speed: float | None
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray | None
    u: np.ndarray
    out: np.ndarray
    alive: np.ndarray
    summary: Record | None


class Results:
    """A run's results: arrays (trajectory.npz's, by name, as attributes), `summary`,
    `run_dir` (None for a run kept in memory), and `recovered` (a `swarm.offline.results.Recovery`
    when `open_run` rebuilt them from the recording of a world that died, else None)."""

    # trajectory.npz's arrays (TICK_ARRAYS, STATIC_ARRAYS), set from `arrays`; the optional ones None when absent
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    u: np.ndarray
    out: np.ndarray
    alive: np.ndarray
    ids: np.ndarray
    role: np.ndarray
    target: np.ndarray
    heading: np.ndarray | None
    missed: np.ndarray | None
    follow: np.ndarray | None  # FollowState codes (swarm.contracts.wire.FOLLOW_STATES); None in older runs
    speed: np.ndarray | None
    orbit_radius: np.ndarray | None
    dt: np.ndarray | None

    def __init__(
        self,
        arrays: dict[str, np.ndarray],
        summary: dict,
        run_dir: Path | None = None,
        recovered: Recovery | None = None,
    ):
        self.arrays = arrays
        self.summary = Summary(summary)
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.recovered = recovered
        for k in STATIC_ARRAYS + TICK_ARRAYS:
            setattr(self, k, arrays.get(k))

    def __repr__(self) -> str:
        end = float(self.t[-1]) if len(self.t) else 0.0
        return (
            f"Results({len(self.ids)} agents, {len(self.t)} rows, t_end={end:g} s, "
            f"converged={self.summary.get('converged')}, run_dir={self.run_dir})"
        )

    @property
    def converged(self) -> bool | None:
        return self.summary.get("converged")

    def column(self, agent_id: int) -> int:
        """The column of agent `agent_id` in the (T, N) arrays."""
        hits = np.flatnonzero(self.ids == agent_id)
        if not hits.size:
            raise KeyError(f"no agent {agent_id} in this run (ids: {', '.join(map(str, self.ids.tolist()))})")
        return int(hits[0])

    def agent(self, agent_id: int) -> AgentTrack:
        """Agent `agent_id`'s columns (views, not copies) and summary entry."""
        j = self.column(agent_id)
        return AgentTrack(
            int(agent_id),
            str(self.role[j]),
            None if self.speed is None else float(self.speed[j]),
            self.t,
            self.x[:, j],
            self.y[:, j],
            None if self.heading is None else self.heading[:, j],
            self.u[:, j],
            self.out[:, j],
            self.alive[:, j],
            self.summary.agents.get(int(agent_id)),
        )

    @property
    def agents(self) -> dict[int, AgentTrack]:
        """Every agent's `AgentTrack`, by id, in scenario order."""
        return {int(a): self.agent(int(a)) for a in self.ids}

    def save(self, out_dir: str | Path, force: bool = False) -> Path:
        """Write trajectory.npz and summary.json into `out_dir` (refused, OutDirError, if it
        holds another run's results, unless `force`); this becomes the run directory."""
        out = Path(out_dir)
        claim_out_dir(out, force)
        # (numpy's stub types **kwds as if they could be its allow_pickle: they are arrays, by name)
        _write_atomic(out / TRAJECTORY_FILE, lambda f: np.savez_compressed(f, **self.arrays))  # type: ignore[arg-type]
        text = json.dumps(self.summary.to_dict(), indent=2, default=_plain) + "\n"
        _write_atomic(out / SUMMARY_FILE, lambda f: f.write(text.encode()))
        self.run_dir = out
        return out

    def plot(self, out_dir: str | Path | None = None, formats: Iterable[str] | None = None) -> list[Path]:
        """Draw the run's figures (swarm/plots: the ones `swarm plot` draws) into `out_dir`,
        default the run directory; in-memory results are saved there first (`save`).
        `formats`: e.g. ("png", "pdf") where swarm/plots offers them. Returns the files."""
        from swarm.plots import render_plots  # lazy: matplotlib (~0.3 s), which reading a run must not pay

        target = self._saved_in(out_dir, "the figures")
        return render_plots(target) if formats is None else render_plots(target, formats=tuple(formats))

    def write_csv(self, out_dir: str | Path | None = None) -> list[Path]:
        """Write csv/agent-<id>.csv, one per agent (swarm/offline/csv_export.py: `swarm export --csv`), into
        `out_dir`, default the run directory (in-memory results are saved there first).
        Returns the files in scenario order."""
        return write_agent_csvs(self._saved_in(out_dir, "the CSV files"))

    def _saved_in(self, out_dir: str | Path | None, what: str) -> Path:
        """The run directory to draw from: `out_dir` (these results saved there if they are not
        its own), else the run directory."""
        target = self.run_dir if out_dir is None else Path(out_dir)
        if target is None:
            raise ValueError(f"these results are in memory: pass out_dir (a directory for the data and {what})")
        if self.run_dir is None or target.resolve() != self.run_dir.resolve():
            self.save(target)
        return target


def _plain(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o)}")


def _write_atomic(path: Path, write: Callable) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def simulate(
    scenario: Scenario | dict | str | Path | Builder,
    duration: float | None = None,
    out: str | Path | None = None,
    *,
    force: bool = False,
    batch: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Results:
    """Run `scenario` in this process, as `swarm sim` does, for `duration` simulated s
    (default the scenario's). `out`: write the run directory there (refused if it holds
    results, unless `force`); else everything stays in memory. `batch`: the batch engine
    (refuses faults and own laws, as `--batch` does: ValueError). `progress(k, ticks)`."""
    s = as_scenario(scenario)
    with_duration(s, duration, source_of(scenario))
    if batch:
        # lazy: the engines (agents' laws, the world's engine: ~16 ms each), which reading a run does not need
        from swarm.offline.batch import refusal, run_batch

        why = refusal(s)
        if why is not None:
            raise ValueError(f"the batch engine does not run this scenario: {why}")
        engine = lambda rec: run_batch([s], duration, progress, rec)[0]  # noqa: E731
    else:
        from swarm.offline.sim import run_sim  # lazy: as swarm.offline.batch above

        engine = lambda rec: run_sim(s, duration, progress, rec)  # noqa: E731
    if out is not None:
        out = Path(out)
        claim_out_dir(out, force)
    t0 = time.perf_counter()
    result = engine(None if out is None else out / RECORDING_FILE)
    wall = time.perf_counter() - t0
    sim_time = duration if duration is not None else s.run.duration
    result.extra["wall_time"] = wall
    result.extra["sim_seconds_per_wall_second"] = sim_time / wall if wall > 0 else None
    if out is None:
        return in_memory(result)
    return in_memory(result, write_run(result, out), out)


def in_memory(result: RunResult, summary: dict | None = None, run_dir: Path | None = None) -> Results:
    """A run of this process (a `swarm.world.recording.RunResult`) as `Results`: what
    `simulate` returns, and `swarm.env.SwarmEnv.result()`. `summary`: the one written to
    `run_dir` (default: the run's, computed now); held as summary.json holds it (plain JSON
    values), whether written or not."""
    summary = result.summary() if summary is None else summary
    return Results(result.recorder.arrays(), json.loads(json.dumps(summary, default=_plain)), run_dir)


def open_run(run_dir: str | Path, recover: bool = True) -> Results:
    """The results of a finished run directory. One whose world died (a recording without
    trajectory.npz) is first rebuilt from its recording (`recover`; the summary then says
    `complete: False`, and `Results.recovered` what was rebuilt). RunReadError, naming the
    file, for anything unreadable; swarm.world.stream.RecordingError if the rebuilt files cannot
    be written."""
    d = Path(run_dir)
    if not d.is_dir():
        raise RunReadError(f"{d}: not a directory")
    try:
        recovered = rebuild(d) if recover else None
    except ValueError as e:
        raise RunReadError(str(e)) from None
    data = load_run(d)  # the checks (shapes, keys) and the summary
    arrays: dict[str, np.ndarray] = {
        "ids": data.ids,
        "role": data.role,
        "target": data.target,
        "t": data.t,
        "x": data.x,
        "y": data.y,
        "u": data.u,
        "out": data.out,
        "alive": data.alive,
    }
    if data.orbit_radius is not None:
        arrays["orbit_radius"] = data.orbit_radius
    with np.load(d / TRAJECTORY_FILE, allow_pickle=False) as z:  # what the plots do not need
        for k in ("heading", "speed", "dt", "missed", "follow"):
            if k in z.files:
                arrays[k] = np.asarray(z[k])
    return Results(arrays, data.summary, d, recovered)


__all__ += ["Builder", "OutDirError", "Recovery", "Scenario", "ScenarioError"]
