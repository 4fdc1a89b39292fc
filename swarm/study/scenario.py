"""The study of one's own scenario (`swarm study scenario`): a scenario file is the template,
and the study says what to vary.

Per seed (drawn afresh for every run, the same draws in every setting, so settings meet the
same starts): uniform jitter of the agents' positions (+-`positions` m), headings
(+-`headings` rad, or uniform over the circle) and speeds (x U(1 - `speeds`, 1 + `speeds`),
a leader's orbit radius scaled with its speed so its angular rate stays); the run's own
`[run] seed` is the study's seed (it drives the random faults: loss, noise).

Per setting (one per combination of the lists): gains C1, C2, `[law.params]` entries, the
sticky rule's selection tuning (`[sensing.tuning]` fields, axes "tuning.<field>"),
sensing range and field of view, the safety filter on or off and its gamma (a scenario with
a [safety] table: what safety costs a law, docs/design/safety.md), and the fault
parameters: the noise std, loss probability and delay of the scenario's noise / loss /
delay faults (0: those faults removed; where the scenario has none, one on every agent for
the whole run is added).

Each run gives one row (the setting's values, the seed, and what `swarm study swarms`
records of a run: converged, settling time, switches, ..., and Robotarium's figures:
collisions, boundary exits, saturations, the least distance). `engine_for` says which engine
runs a study: the batch engine (swarm/offline/batch.py) when it runs every setting's
scenario (a follower law of one's own only if it declares `vectorised = True`: swarm/agents/
batch.py `follower_law_of`), else `swarm sim`'s per-agent engine, one run per job.
"""

from __future__ import annotations

import itertools
import math
import statistics
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarm.contracts.scenario import Scenario, parse_scenario
from swarm.contracts.vocabulary import EventKind
from swarm.offline.batch import refusal, run_batch
from swarm.offline.sim import run_sim
from swarm.study.swarms import SAFETY_COLUMNS, STATE_COLUMNS, is_true, run_outcome, safety_totals, state_totals

# the axes a setting may sweep, in the order of the CSV's columns ("param.<name>" for [law.params])
AXES = ("c1", "c2", "range", "fov", "noise", "loss", "delay", "safety", "gamma")
FAULT_FIELD = {"noise": "std", "loss": "probability", "delay": "delay"}


@dataclass(frozen=True)
class Jitter:
    """What every seed draws afresh (0: nothing)."""

    positions: float = 0.0  # +- m on x and y
    headings: float = 0.0  # +- rad; math.inf: uniform over the circle
    speeds: float = 0.0  # relative: speed x U(1 - speeds, 1 + speeds)


@dataclass(frozen=True)
class Template:
    """The scenario file, as a document to vary, and where its laws are found."""

    data: dict
    source: str
    law_dirs: tuple[str, ...] = ()
    duration: float | None = None  # simulated s per run (default: the scenario's)


@dataclass(frozen=True)
class Setting:
    """One combination of the swept values: (axis, value) pairs, axes as in AXES,
    "param.<name>" or "tuning.<name>"."""

    values: tuple[tuple[str, float], ...] = field(default_factory=tuple)

    def label(self) -> str:
        return " ".join(f"{k.removeprefix('param.')}={v:g}" for k, v in self.values) or "template"


def _tuned(sensing: dict, name: str, value: float) -> dict:
    """[sensing] with [sensing.tuning]'s `name` set to `value` (swarm/contracts/tuning.py)."""
    return {**sensing, "tuning": {**(sensing.get("tuning") or {}), name: value}}


def settings_of(sweeps: Mapping[str, Sequence[float]]) -> list[Setting]:
    """One setting per combination of the swept lists (axes in the order given)."""
    axes = list(sweeps)
    return [Setting(tuple(zip(axes, combo))) for combo in itertools.product(*(sweeps[a] for a in axes))]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _faults(faults: list[dict], kind: str, value: float, duration: float) -> list[dict]:
    """The scenario's `kind` faults with their parameter set to `value` (0: removed); one on
    every agent for the whole run where there was none."""
    key = FAULT_FIELD[kind]
    if value == 0:
        return [f for f in faults if f["kind"] != kind]
    if any(f["kind"] == kind for f in faults):
        return [{**f, key: value} if f["kind"] == kind else f for f in faults]
    return [*faults, {"at": 0.0, "kind": kind, "duration": duration, key: value}]


def varied(template: Template, setting: Setting, jitter: Jitter, seed: int) -> Scenario:
    """The template with the setting's values and seed `seed`'s draws."""
    d: dict[str, Any] = {
        k: (dict(v) if isinstance(v, dict) else list(v) if isinstance(v, list) else v) for k, v in template.data.items()
    }
    run = {**d["run"], "seed": seed}
    if template.duration is not None:
        run["duration"] = template.duration
    d["run"] = run
    d["name"] = f"{d.get('name') or 'scenario'}-{seed}"
    d["gains"], d["sensing"] = dict(d["gains"]), dict(d["sensing"])
    law = dict(d.get("law") or {})
    law["params"] = dict(law.get("params") or {})
    faults = [dict(f) for f in d.get("faults") or []]
    for key, v in setting.values:
        if key in ("c1", "c2"):
            d["gains"][key] = v
        elif key == "range":
            d["sensing"]["range"] = None if math.isinf(v) else v
        elif key == "fov":
            d["sensing"]["fov"] = None if v >= 2 * math.pi else v
        elif key in FAULT_FIELD:
            faults = _faults(faults, key, v, run["duration"])
        elif key in ("safety", "gamma"):  # [safety]: filtering on (1) or measuring only (0); its gamma
            if d.get("safety") is None:
                raise ValueError(f"axis {key!r}: the scenario has no [safety] table")
            name = {"safety": "enabled", "gamma": "gamma"}[key]
            d["safety"] = {**d["safety"], name: bool(v) if key == "safety" else v}
        elif key.startswith("param."):
            law["params"][key.removeprefix("param.")] = v
        elif key.startswith("tuning."):
            d["sensing"] = _tuned(d["sensing"], key.removeprefix("tuning."), v)
        else:
            raise ValueError(f"unknown axis {key!r}")
    d["law"], d["faults"] = law, faults
    rng = np.random.default_rng([seed, 25])
    agents = []
    for a in d["agents"]:
        a = dict(a)
        dx, dy, dh, ds = rng.uniform(-1.0, 1.0, size=4)  # four draws per agent, whatever is varied
        if jitter.positions:
            a["x"] += jitter.positions * dx
            a["y"] += jitter.positions * dy
        if math.isinf(jitter.headings):
            a["heading"] = math.pi * dh
        elif jitter.headings:
            a["heading"] = _wrap(a["heading"] + jitter.headings * dh)
        if jitter.speeds:
            f = 1.0 + jitter.speeds * ds
            a["speed"] *= f
            if a.get("orbit_radius") is not None:
                a["orbit_radius"] *= f
        agents.append(a)
    d["agents"] = agents
    return parse_scenario(d, f"{template.source} (seed {seed}, {setting.label()})", template.law_dirs)


# -- which engine -----------------------------------------------------------------------------


def engine_for(scenarios: Sequence[Scenario]) -> tuple[str, str]:
    """("batch" | "per-agent", why) for a study whose settings give these scenarios (one
    per setting): the batch engine if it runs all of them (a law of one's own only if
    declared vectorised)."""
    for s in scenarios:
        why = refusal(s)
        if why is not None:
            return "per-agent", why
    law = scenarios[0].gains.law if scenarios else "bearing"
    return "batch", ("the built-in 'bearing' law" if law == "bearing" else f"follower law {law!r} is vectorised")


# -- the workers ------------------------------------------------------------------------------

Job = tuple[Template, Setting, Jitter, tuple[int, ...]]  # a setting's seeds: one run each, or one batch


def _law_path(template: Template) -> None:
    """A spawned worker finds the template's law modules as `swarm sim` would."""
    for d in template.law_dirs:
        if d not in sys.path:
            sys.path.append(d)  # appended, as swarm.contracts.laws does


def run_one(job: Job) -> list[dict]:
    """Worker (per-agent engine): each seed of the job through `swarm sim`'s engine."""
    template, setting, jitter, seeds = job
    _law_path(template)
    out = []
    for seed in seeds:
        t0 = time.perf_counter()
        res = run_sim(varied(template, setting, jitter, seed))
        out.append(row(setting, seed, res, time.perf_counter() - t0))
    return out


def run_chunk(job: Job) -> list[dict]:
    """Worker (batch engine): the job's seeds as one batch; wall_s is the batch's wall time
    shared out over its runs."""
    template, setting, jitter, seeds = job
    _law_path(template)
    t0 = time.perf_counter()
    scenarios = [varied(template, setting, jitter, sd) for sd in seeds]
    results = run_batch(scenarios, lean=True)
    wall = (time.perf_counter() - t0) / len(seeds)
    return [row(setting, sd, r, wall) for sd, r in zip(seeds, results)]


def jobs_of(template: Template, settings: Sequence[Setting], jitter: Jitter, seeds: int, per_job: int) -> list[Job]:
    """Each setting's seeds 0..seeds-1 in jobs of `per_job` runs."""
    return [
        (template, st, jitter, tuple(range(k, min(seeds, k + per_job))))
        for st in settings
        for k in range(0, seeds, per_job)
    ]


def stubs(job: Job) -> list[dict]:
    """The key columns (setting, its values, seed) of each run of a job."""
    _, setting, _, seeds = job
    return [{"setting": setting.label(), **dict(setting.values), "seed": sd} for sd in seeds]


def subset(job: Job, keep: list[int]) -> Job:
    """The job with only the runs `keep` (indices into its seeds)."""
    template, setting, jitter, seeds = job
    return (template, setting, jitter, tuple(seeds[i] for i in keep))


KEY_COLUMNS = ["setting", "seed"]  # what names a run of a scenario study


def row(setting: Setting, seed: int, res, wall: float) -> dict:
    """The CSV row of one run."""
    crashes = sum(1 for e in res.events if e.get("kind") == EventKind.CRASH)
    return {
        "setting": setting.label(),
        **{k: v for k, v in setting.values},
        "seed": seed,
        **run_outcome(res),
        "crashes": crashes,
        "wall_s": wall,
    }


def columns(settings: Sequence[Setting]) -> list[str]:
    axes = [k for k, _ in settings[0].values] if settings else []
    return [
        "setting",
        *axes,
        "seed",
        "converged",
        "settling_time",
        "switches",
        "switches_max",
        "switch_counts",
        "unrooted",
        "searching_s",
        "searching_max_s",
        "losses",
        "loss_switches_max",
        *SAFETY_COLUMNS,
        *STATE_COLUMNS,
        "crashes",
        "wall_s",
    ]


def summarise(rows: list[dict], settings: Sequence[Setting]) -> list[dict]:
    """One line per setting (in the settings' order; settings with no row left out): runs
    (and how many ended at the run timeout), converged share over every run (a timed-out one
    did not converge), settling times of the converged runs, switches per follower, crashes
    (over the runs that finished)."""
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(str(r["setting"]), []).append(r)
    out = []
    for st in settings:
        every = groups.get(st.label(), [])
        if not every:
            continue
        rs = [r for r in every if r.get("status") in (None, "ok")]
        conv = [r for r in rs if is_true(r["converged"])]
        settle = sorted(float(r["settling_time"]) for r in conv if math.isfinite(float(r["settling_time"])))
        per_agent = [int(c) for r in rs for c in str(r["switch_counts"]).split(";") if c != ""]
        out.append(
            {
                "setting": st.label(),
                **{k: v for k, v in st.values},
                "runs": len(every),
                "timeouts": len(every) - len(rs),
                "converged": len(conv),
                "converged_fraction": len(conv) / len(every),
                "settling_median_s": statistics.median(settle) if settle else math.nan,
                "settling_p90_s": settle[min(len(settle) - 1, int(0.9 * len(settle)))] if settle else math.nan,
                "switches_median": statistics.median(per_agent) if per_agent else math.nan,
                "switches_max": max(per_agent, default=0),
                "crashes": sum(int(r.get("crashes", 0)) for r in rs),
                **safety_totals(rs),
                **state_totals(rs),
            }
        )
    return out
