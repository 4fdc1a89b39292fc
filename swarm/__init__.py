"""swarm: an agent-per-process runtime for bearing-based circumnavigation over zenoh.

`import swarm` is the Python API (swarm/api/runs.py; docs/reference/api.md): `swarm.load`,
`swarm.from_dict`, `swarm.Builder`, `swarm.simulate`, `swarm.open_run`, `swarm.up`,
`swarm.launch`, `swarm.Results`..., and a live run: `swarm.connect`, `swarm.runs` (swarm/api/live.py);
every robot stopped at once: `swarm.estop` (swarm/api/estop.py); batch studies: `swarm.study`
(swarm/study/api.py); the errors are
swarm/contracts/errors.py's. Every name is imported on first use (module `__getattr__`), so
`import swarm.contracts.wire` in an agent process still costs nothing more than it did.
"""

from importlib import import_module

__version__ = "0.1.0"  # the one place the version is written (pyproject.toml reads it)

_EXPORTS = {
    "api.runs": (
        "Builder",
        "OutDirError",
        "Record",
        "Recovery",
        "Results",
        "RunReadError",
        "Scenario",
        "ScenarioError",
        "Summary",
        "AgentTrack",
        "open_run",
        "simulate",
    ),
    "api.launch": ("Launch", "UpOutcome", "launch"),
    "api.scenario": ("from_dict", "load", "to_toml"),
    "api.live": ("Live", "LiveState", "connect", "runs"),
    "api.estop": ("Estopped", "estop"),
    "api.up": ("UpRun", "up"),
    "contracts.errors": ("LiveError", "NoRunError", "StoppedAnswering", "SwarmError", "UpError", "UsageError"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}
_SUBPACKAGES = ("study",)  # `swarm.study.run_scenario(...)` after a bare `import swarm` (swarm/study/api.py)

__all__ = sorted([*_WHERE, *_SUBPACKAGES])


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return import_module(f"swarm.{name}")  # (the import binds it here)
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'swarm' has no attribute {name!r}")
    value = getattr(import_module(f"swarm.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE) | set(_SUBPACKAGES))
