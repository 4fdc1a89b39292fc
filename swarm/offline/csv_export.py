"""`swarm export DIR --csv`: a run's trajectory as one CSV per agent, for spreadsheets,
pandas or pgfplots (``csv/agent-<id>.csv`` in the run directory, one row per tick, the
same rows as trajectory.npz).

Columns (`COLUMNS`); ``nan`` where a value is undefined:

    t                s     time of the tick
    x, y             m     position
    heading          rad   heading (nan if trajectory.npz has none)
    u                rad/s turn rate applied over [t, t + dt); nan in the last row and while not alive
                           (0 while a dropped agent coasts: on_dropout = "coast")
    out              -     out-neighbour id chosen at the tick, -1 for none (always -1 for a leader)
    alive            0/1   controlled by a live process at the tick
    r                m     distance from the target
    expected_radius  m     R_i from the final graph (summary.json; a leader's orbit radius), nan if none
    radial_error     m     r - expected_radius (signed: positive outside the expected orbit)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from swarm.world.recording import TRAJECTORY_FILE
from swarm.world.run_reader import RunData, load_run

CSV_DIR = "csv"
COLUMNS = ("t", "x", "y", "heading", "u", "out", "alive", "r", "expected_radius", "radial_error")
_FORMATS = ("%.10g", "%.9g", "%.9g", "%.9g", "%.9g", "%d", "%d", "%.9g", "%.9g", "%.9g")


def csv_name(agent_id: int) -> str:
    return f"agent-{int(agent_id)}.csv"


def expected_by_column(run: RunData) -> np.ndarray:
    """(N,) expected orbit radius per column: summary.json's `expected_radius` (final
    graph), else a leader's own orbit radius; NaN when neither is known."""
    out = np.full(run.n_agents, np.nan)
    agents = run.summary.get("agents")
    for j, a in enumerate(run.ids):
        info = agents.get(str(int(a))) if isinstance(agents, dict) else None
        r = info.get("expected_radius") if isinstance(info, dict) else None
        if isinstance(r, (int, float)) and math.isfinite(r) and r > 0:
            out[j] = float(r)
        elif run.is_leader(j) and run.orbit_radius is not None and math.isfinite(run.orbit_radius[j]):
            out[j] = float(run.orbit_radius[j])
    return out


def _headings(run_dir: Path, shape: tuple[int, int]) -> np.ndarray:
    try:
        with np.load(run_dir / TRAJECTORY_FILE, allow_pickle=False) as z:
            if "heading" in z.files and z["heading"].shape == shape:
                return np.asarray(z["heading"], dtype=float)
    except Exception:  # load_run has already vetted the file; heading is optional
        pass
    return np.full(shape, np.nan)


def agent_table(run: RunData, heading: np.ndarray, j: int, expected: float) -> np.ndarray:
    """(T, len(COLUMNS)) rows of the agent in column `j`."""
    tx, ty = run.target
    r = np.hypot(run.x[:, j] - tx, run.y[:, j] - ty)
    return np.column_stack(
        [
            run.t,
            run.x[:, j],
            run.y[:, j],
            heading[:, j],
            run.u[:, j],
            run.out[:, j],
            run.alive[:, j].astype(float),
            r,
            np.full(run.n_rows, expected),
            r - expected,
        ]
    )


def write_agent_csvs(run_dir: Path) -> list[Path]:
    """Write ``csv/agent-<id>.csv`` for every agent of the run in `run_dir`; return the
    paths in scenario order. Raises RunReadError (a bad trajectory.npz / summary.json)."""
    run_dir = Path(run_dir)
    run = load_run(run_dir)
    heading = _headings(run_dir, (run.n_rows, run.n_agents))
    expected = expected_by_column(run)
    folder = run_dir / CSV_DIR
    folder.mkdir(exist_ok=True)
    paths = []
    for j, a in enumerate(run.ids):
        path = folder / csv_name(int(a))
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            np.savetxt(
                tmp,
                agent_table(run, heading, j, float(expected[j])),
                fmt=list(_FORMATS),
                delimiter=",",
                header=",".join(COLUMNS),
                comments="",
            )
            tmp.replace(path)
        finally:
            tmp.unlink(missing_ok=True)
        paths.append(path)
    return paths
