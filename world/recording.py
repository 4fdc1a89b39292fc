"""A run's recording: every tick of ground truth, written as trajectory.npz, plus
summary.json. The layout is documented in README.md ("Outputs of a run"); the reader
is world/run_reader.py.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.contracts.scenario import Scenario
from world.metrics import agent_metrics, converged, recovery, relative_errors, switch_ticks

TRAJECTORY_FILE = "trajectory.npz"
SUMMARY_FILE = "summary.json"


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

    def add_agent(self, scenario: Scenario) -> None:
        """One more column (an agent added at run time); earlier rows say it was absent."""
        self.scenario = scenario
        rows = self.t.shape[0]
        grow = lambda a, fill: np.concatenate([a, np.full((rows, 1), fill, dtype=a.dtype)], axis=1)  # noqa: E731
        self.x, self.y, self.heading, self.u = (grow(a, np.nan) for a in (self.x, self.y, self.heading, self.u))
        self.out = grow(self.out, -1)
        self.alive = grow(self.alive, False)

    def record(self, tick: int, time: float, x, y, heading, u, out, alive, missed: int = 0) -> None:
        """Store tick `tick`: pose at t_k and the turn rate applied over [t_k, t_k+1)."""
        self.t[tick] = time
        self.x[tick] = x
        self.y[tick] = y
        self.heading[tick] = heading
        self.u[tick] = u
        self.out[tick] = out
        self.alive[tick] = alive
        self.missed[tick] = missed
        self.rows = max(self.rows, tick + 1)

    def arrays(self) -> dict[str, np.ndarray]:
        s = self.scenario
        n = self.rows
        return {
            "ids": np.array(s.ids, dtype=np.int64),
            "role": np.array([a.role for a in s.agents]),
            "speed": np.array([a.speed for a in s.agents], dtype=float),
            "orbit_radius": np.array([a.orbit_radius if a.orbit_radius else math.nan for a in s.agents]),
            "target": np.array([s.target.x, s.target.y], dtype=float),
            "dt": np.array(s.run.dt),
            "t": self.t[:n], "x": self.x[:n], "y": self.y[:n], "heading": self.heading[:n],
            "u": self.u[:n], "out": self.out[:n], "alive": self.alive[:n], "missed": self.missed[:n],
        }


@dataclass
class RunResult:
    scenario: Scenario
    recorder: Recorder
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
            agents = agent_metrics(ids=a["ids"], roles=a["role"], speeds=a["speed"],
                                   orbit_radius=a["orbit_radius"], t=a["t"], x=a["x"], y=a["y"],
                                   alive=a["alive"], out_final=a["out"][-1], target=a["target"],
                                   switches=counts)
        for aid, more in self.agent_extra.items():
            if aid in agents:
                agents[aid].update(more)
        ticks = max(len(a["t"]) - 1, 0)
        faults = []
        if self.scenario.faults and len(a["t"]) > 1:
            err = relative_errors(ids=a["ids"], roles=a["role"], speeds=a["speed"],
                                  orbit_radius=a["orbit_radius"], x=a["x"], y=a["y"], alive=a["alive"],
                                  out=a["out"], target=a["target"])
            specs = [{"index": i, **{k: v for k, v in f.model_dump().items() if v is not None}}
                     for i, f in enumerate(self.scenario.faults)]
            faults = recovery(specs, a["t"], err, a["missed"], self.events)
        return {
            "scenario": self.scenario.name,
            "converged": converged(agents),
            "ticks": ticks,
            "selection": self.scenario.sensing.selection,
            "switches": switches,
            "sim_time": float(a["t"][-1]) if len(a["t"]) else 0.0,
            "dt": self.scenario.run.dt,
            "agents": agents,
            "events": self.events,
            "faults": faults,
            **self.extra,
        }


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


def write_run(result: RunResult, out_dir: Path) -> dict:
    """Write trajectory.npz and summary.json into out_dir; returns the summary."""
    out_dir.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out_dir / TRAJECTORY_FILE, **result.recorder.arrays())
    summary = result.summary()
    tmp = out_dir / f"{SUMMARY_FILE}.tmp"
    tmp.write_text(json.dumps(summary, indent=2, default=_json_default) + "\n")
    tmp.replace(out_dir / SUMMARY_FILE)
    return summary
