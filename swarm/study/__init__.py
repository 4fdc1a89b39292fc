"""`swarm.study`: batch studies as Python functions (`run_swarms`, `run_gains`,
`run_scenario`, each returning a `StudyResult`; `plan_*` and `execute` to run a study's jobs
with an executor: this machine's processes, a Dask cluster (`dask_executor`) or one's own:
swarm/study/api.py, swarm/study/plan.py, swarm/study/cluster.py; docs/reference/api.md#study).
`swarm study` is the command line over them.

The modules: random swarms (`swarms`), gains (`gains`), one's own scenario (`scenario`, with
`sweeps` for what it may vary), run on a process pool (`pool`) or the batch engine (`batch`),
with their figures (`figures`). The names below are imported on first use: a worker process
that imports `swarm.study.scenario` pays for nothing else.
"""

from importlib import import_module

_EXPORTS = {
    "api": ("plan_gains", "plan_scenario", "plan_swarms", "run_gains", "run_scenario", "run_swarms"),
    "plan": ("Executor", "StudyExecutor", "StudyPlan", "StudyResult", "execute", "local_executor"),
    "cluster": ("dask_executor",),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'swarm.study' has no attribute {name!r}")
    value = getattr(import_module(f"swarm.study.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
