"""`swarm study`: does the law converge for my kind of swarm? Batch runs of the in-process
engine on a process pool, rows streamed to CSV as they finish: by default many runs per
job through the batch engine (swarm/study/batch.py), or one run per job through
`swarm sim`'s per-agent engine (`run_swarm`, `run_gain`); the rows are the same.

Two studies:

- **swarms** (here): random swarms drawn from a few options (agents, leaders, area,
  speeds, sensing range and field of view, selection rule, gains), one run per (setting,
  seed). A swarm depends only on (seed, n, leaders, area, speeds, omega), so every
  selection rule and sensing range of one study meets the same swarms.
- **gains** (swarm/study/gains.py): one follower behind a leader that is already on its
  orbit, for a grid of (C1, C2) and speed ratios: where does the law settle, and how fast?

Generation, the workers and the summaries are pure functions of their arguments;
swarm/study/pool.py runs jobs on a process pool and writes the tables.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, fields

import numpy as np

from swarm.contracts.scenario import Scenario, parse_scenario
from swarm.contracts.vocabulary import FollowState
from swarm.offline.sim import run_sim
from swarm.world.core import WorldCore
from swarm.world.metrics import switch_ticks


@dataclass(frozen=True)
class SwarmSetting:
    """One setting of the swarms study (every field a CSV column)."""

    n: int = 10  # agents
    leaders: int = 2
    selection: str = "sticky"
    range: float = math.inf  # sensing range (m); inf: unlimited
    fov: float = 2 * math.pi  # field of view (rad)
    area: float = 120.0  # side of the square the agents start in (m), centred on the target
    speed_min: float = 15.0  # m/s
    speed_max: float = 40.0
    omega: float = 1.0  # every leader's angular rate on its orbit (rad/s): R_L = v_L / omega
    c1: float = 1.0
    c2: float = 0.5
    duration: float = 500.0  # s
    dt: float = 0.05  # s
    safety_radius: float = 0.0  # m: a [safety] table measuring collisions at this radius (no filter); 0: none

    def label(self) -> str:
        rng = "unlimited" if math.isinf(self.range) else f"{self.range:g} m"
        fov = "" if self.fov >= 2 * math.pi else f", fov {self.fov:.2f}"
        return f"N={self.n} L={self.leaders} {self.selection} range {rng}{fov}"


def random_swarm(setting: SwarmSetting, seed: int) -> Scenario:
    """The random swarm `seed` of a setting: ids 1..n, leaders first, uniform positions in
    the area, uniform headings and speeds, leaders orbiting ccw at R_L = v_L / omega."""
    rng = np.random.default_rng([seed, setting.n, setting.leaders])
    half = setting.area / 2
    xy = rng.uniform(-half, half, size=(setting.n, 2))
    heading = rng.uniform(-math.pi, math.pi, size=setting.n)
    speed = rng.uniform(setting.speed_min, setting.speed_max, size=setting.n)
    agents = []
    for k in range(setting.n):
        a = {
            "id": k + 1,
            "role": "leader" if k < setting.leaders else "follower",
            "x": float(xy[k, 0]),
            "y": float(xy[k, 1]),
            "heading": float(heading[k]),
            "speed": float(speed[k]),
        }
        if k < setting.leaders:
            a["orbit_radius"] = float(speed[k]) / setting.omega
        agents.append(a)
    sensing: dict = {"selection": setting.selection}
    if math.isfinite(setting.range):
        sensing["range"] = setting.range
    if setting.fov < 2 * math.pi:
        sensing["fov"] = setting.fov
    data = {
        "name": f"study-{seed}",
        "run": {"dt": setting.dt, "duration": setting.duration, "seed": seed},
        "gains": {"c1": setting.c1, "c2": setting.c2},
        "sensing": sensing,
        "agents": agents,
    }
    if setting.safety_radius > 0:  # measured only: these agents have no turn-rate limit to filter within
        data["safety"] = {"radius": setting.safety_radius, "enabled": False}
    return parse_scenario(data, f"random swarm (seed {seed})")


def cut_off_at_start(s: Scenario) -> bool:
    """Some follower has no path to a leader in the sensing graph at t = 0: it cannot be
    rooted before it moves (only possible with a range or field of view)."""
    sensed = WorldCore(s).sensing()[0]
    reach = {k for k, a in enumerate(s.agents) if a.role == "leader"}
    grew = True
    while grew:
        new = {i for i in range(len(s.agents)) if i not in reach and any(sensed[i, j] for j in reach)}
        reach |= new
        grew = bool(new)
    return len(reach) < len(s.agents)


@dataclass(frozen=True)
class SwarmRow:
    """The outcome of one run (a CSV row, after the setting's columns)."""

    seed: int
    converged: bool  # every live agent within 1% of its expected radius at the end
    cut_off: bool  # see cut_off_at_start: counted like every run, and also shown apart
    settling_time: float  # s, the last agent into the 2% band for good; nan if not settled
    switches: int  # all followers' out-neighbour changes
    switches_max: int  # the most any one follower made
    switch_counts: str  # per follower, ';'-separated (for medians over agents)
    unrooted: int  # followers with no path to a live leader at the end
    searching_s: float  # s a follower spent with nobody to steer by, mean over followers
    searching_max_s: float  # ... the most any one follower spent
    losses: int  # all followers' losses of a committed out-neighbour (selection "sticky")
    loss_switches_max: int  # the most changes of out-neighbour any one loss cost
    # Robotarium's figures, from summary.json's "safety" (a scenario with a [safety] table; else
    # None, an empty cell): `safety_outcome`
    collisions: int | None
    boundary_exits: int | None
    saturations: int | None
    min_distance: float | None
    interventions: int | None
    infeasible: int | None
    wall_s: float


def run_swarm(job: tuple[SwarmSetting, int]) -> dict:
    """Worker: one random swarm through `swarm sim`'s engine; a flat dict for the CSV."""
    setting, seed = job
    t0 = time.perf_counter()
    s = random_swarm(setting, seed)
    cut = cut_off_at_start(s)
    res = run_sim(s)
    return swarm_row(setting, seed, cut, res, time.perf_counter() - t0)


def swarm_row(setting: SwarmSetting, seed: int, cut: bool, res, wall: float) -> dict:
    """The CSV row of one run's RunResult (either engine's)."""
    outcome = run_outcome(res)
    states = {k: outcome.pop(k) for k in STATE_COLUMNS}
    row = {**asdict(setting), **asdict(SwarmRow(seed=seed, cut_off=cut, wall_s=wall, **outcome))}
    return {**{k: v for k, v in row.items() if k != "wall_s"}, **states, "wall_s": wall}


def run_outcome(res) -> dict:
    """What a study records of one run's RunResult (either engine's): SwarmRow's fields
    from `converged` to `loss_switches_max`, `cut_off` excepted."""
    summary = res.summary()
    a = res.recorder.arrays()
    follower = a["role"] == "follower"
    counts = [len(k) for k, f in zip(switch_ticks(a["out"], a["alive"]), follower) if f]
    agents = summary["agents"].values()
    settle = [v["settling_time"] for v in agents]
    dt = float(a["t"][1] - a["t"][0]) if len(a["t"]) > 1 else 0.0
    searching = ((a["out"][:-1] < 0) & a["alive"][:-1]).sum(axis=0)[follower] * dt  # the last row is the end
    fol = [v for v in agents if v["role"] == "follower"]
    return {
        "converged": bool(summary["converged"]),
        "settling_time": max(settle) if settle and None not in settle else math.nan,
        "switches": sum(counts),
        "switches_max": max(counts, default=0),
        "switch_counts": ";".join(map(str, counts)),
        "unrooted": sum(1 for v in fol if v["root"] is None),
        "searching_s": float(searching.mean()) if searching.size else 0.0,
        "searching_max_s": float(searching.max(initial=0.0)),
        "losses": sum(v.get("losses", 0) for v in fol),
        "loss_switches_max": max((v.get("loss_switches_max", 0) for v in fol), default=0),
        **safety_outcome(summary),
        **state_outcome(summary),
    }


SAFETY_COLUMNS = ("collisions", "boundary_exits", "saturations", "min_distance", "interventions", "infeasible")


def safety_outcome(summary: dict) -> dict:
    """A run's safety figures for its row (docs/reference/outputs.md#safety): collisions (pair
    spells closer than the radius), boundary exits, saturations (agent-ticks at the turn-rate
    limit), the least distance between two agents (m), the filter's interventions and its
    agent-ticks with no safe command; None each without a [safety] table."""
    safety = summary.get("safety") or {}
    return {k: safety.get(k) for k in SAFETY_COLUMNS}


# s per follower in each selection state (swarm.contracts.vocabulary.FollowState), from summary.json's
# per-agent `state_s` ({state: s}); nan where the run's summary has none
STATE_COLUMNS = tuple(f"state_s_{s.value}" for s in FollowState)


def state_outcome(summary: dict) -> dict:
    """A run's time in each selection state for its row: the mean over its followers of
    summary.json's `agents.<id>.state_s` (s per follower; a state a follower never was in counts
    0); nan each when no follower has `state_s` (an engine or version that does not count them)."""
    fol = [v for v in summary.get("agents", {}).values() if v.get("role") == "follower"]
    counted = [v["state_s"] for v in fol if isinstance(v.get("state_s"), dict)]
    if not counted:
        return dict.fromkeys(STATE_COLUMNS, math.nan)
    return {f"state_s_{s.value}": sum(float(c.get(s.value, 0.0)) for c in counted) / len(counted) for s in FollowState}


def state_totals(rows: list[dict]) -> dict:
    """A setting's time per selection state: the mean over its runs of each run's per-follower
    mean (runs without the figures left out); {} when no run had them."""
    out = {}
    for k in STATE_COLUMNS:
        vals = [float(r[k]) for r in rows if r.get(k) not in (None, "") and math.isfinite(float(r[k]))]
        if vals:
            out[k] = sum(vals) / len(vals)
    return out


def safety_totals(rows: list[dict]) -> dict:
    """A setting's safety figures over its runs (runs without them left out): the sums, the
    least distance, and `safe_runs` (runs without a collision or a boundary exit); {} when no
    run was measured."""
    measured = [r for r in rows if r.get("collisions") not in (None, "")]
    if not measured:
        return {}
    total = {k: sum(int(r[k]) for r in measured) for k in SAFETY_COLUMNS if k != "min_distance"}
    dmin = [float(r["min_distance"]) for r in measured if r.get("min_distance") not in (None, "")]
    return {
        **total,
        "min_distance": min(dmin, default=math.nan),
        "safe_runs": sum(1 for r in measured if int(r["collisions"]) == 0 and int(r["boundary_exits"]) == 0),
    }


def finished(rows: list[dict]) -> list[dict]:
    """The rows of runs that finished (not ended at the run timeout: swarm/study/plan.py)."""
    return [r for r in rows if r.get("status") in (None, "ok")]


def swarm_key_columns() -> list[str]:
    """What names a run of the swarms study: its setting's columns and its seed."""
    return [f.name for f in fields(SwarmSetting)] + ["seed"]


def swarm_stubs(job: tuple[SwarmSetting, int | tuple[int, ...]]) -> list[dict]:
    """The key columns of each run of a job (one seed, or a chunk's seeds)."""
    setting, seeds = job
    return [{**asdict(setting), "seed": sd} for sd in (seeds if isinstance(seeds, tuple) else (seeds,))]


def swarm_subset(job: tuple[SwarmSetting, int | tuple[int, ...]], keep: list[int]) -> tuple:
    """The job with only the runs `keep` (indices into its seeds)."""
    setting, seeds = job
    if not isinstance(seeds, tuple):
        return job
    return (setting, tuple(seeds[i] for i in keep))


def swarm_jobs(settings: Iterable[SwarmSetting], seeds: Iterable[int]) -> list[tuple[SwarmSetting, int]]:
    seeds = list(seeds)
    return [(st, sd) for st in settings for sd in seeds]


def swarm_columns() -> list[str]:
    outcome = [f.name for f in fields(SwarmRow) if f.name != "wall_s"]
    return [f.name for f in fields(SwarmSetting)] + outcome + [*STATE_COLUMNS, "wall_s"]


def setting_of(row: dict) -> tuple:
    return tuple(row[f.name] for f in fields(SwarmSetting))


def summarise_swarms(rows: list[dict]) -> list[dict]:
    """One line per setting: runs (and how many ended at the run timeout), converged fraction
    over every run (a timed-out one did not converge; and, apart, how many were cut off at
    t = 0 and how those fared), settling times, switches per follower, time spent searching and
    the worst loss's switches (over the runs that finished)."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(setting_of(r), []).append(r)
    out = []
    for key, every in groups.items():
        setting = SwarmSetting(*key)
        rs = finished(every)  # a run ended at the timeout counts as a run that did not converge
        cut = [r for r in rs if is_true(r["cut_off"])]
        conv = [r for r in rs if is_true(r["converged"])]
        settle = sorted(float(r["settling_time"]) for r in conv if math.isfinite(float(r["settling_time"])))
        per_agent = [int(c) for r in rs for c in str(r["switch_counts"]).split(";") if c != ""]
        search = sorted(float(r.get("searching_s", math.nan)) for r in rs)
        out.append(
            {
                "setting": setting.label(),
                "runs": len(every),
                "timeouts": len(every) - len(rs),
                "cut_off": len(cut),
                "cut_off_converged": sum(1 for r in cut if is_true(r["converged"])),
                "converged": len(conv),
                "converged_fraction": len(conv) / len(every),
                "settling_median_s": statistics.median(settle) if settle else math.nan,
                "settling_p90_s": settle[min(len(settle) - 1, int(0.9 * len(settle)))] if settle else math.nan,
                "switches_median": statistics.median(per_agent) if per_agent else math.nan,
                "switches_p90": sorted(per_agent)[int(0.9 * (len(per_agent) - 1))] if per_agent else math.nan,
                "switches_max": max(per_agent, default=0),
                "searching_median_s": statistics.median(search) if search else math.nan,
                "searching_max_s": max((float(r.get("searching_max_s", math.nan)) for r in rs), default=math.nan),
                "losses": sum(int(r.get("losses", 0)) for r in rs),
                "loss_switches_max": max((int(r.get("loss_switches_max", 0)) for r in rs), default=0),
                **safety_totals(rs),
                **state_totals(rs),
                **{k: getattr(setting, k) for k in ("n", "leaders", "selection", "range", "fov")},
            }
        )
    return out


def is_true(v) -> bool:
    return v is True or str(v) == "True"
