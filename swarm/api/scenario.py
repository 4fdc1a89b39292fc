"""Scenarios for the Python API (swarm/api/runs.py): read from a file, validated from a dict,
or made in code, and written back as TOML.

- `load(path)`: a scenario file, as every command reads it (`load_scenario`).
- `from_dict(data)`: a dict of the file's shape (`{"run": {...}, "gains": {...},
  "agents": [{...}, ...]}`), through the same checks.
- `Builder`: a scenario in code: `Builder("demo", dt=0.05, duration=20, c1=1, c2=0.5)`,
  then `.leader(...)`, `.follower(...)`, `.fault(...)`, `.build()`.
- `as_scenario(x)`: any of those (or a Scenario) as a Scenario; what every API call takes.
- `to_toml(scenario)`: the file that loads back to the same scenario (what `swarm.up`
  hands its processes when given a scenario that is not a file).

Every problem is a `ScenarioError` whose message is the one `swarm check` prints for a
file: the source on the first line, then one line per field (`agents[3].speed: Input
should be greater than 0`).
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarm.contracts.scenario import Scenario, ScenarioError, load_scenario, parse_scenario
from swarm.contracts.scenario_tables import GainsSpec, RunSpec, SensingSpec

if TYPE_CHECKING:
    from pydantic import BaseModel

__all__ = ["Builder", "Scenario", "ScenarioError", "as_scenario", "from_dict", "load", "to_toml", "with_duration"]

_TABLES: dict[str, type[BaseModel]] = {"run": RunSpec, "gains": GainsSpec, "sensing": SensingSpec}


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file (TOML); ScenarioError naming the file and the field."""
    return load_scenario(path)


def from_dict(data: dict, source: str = "<dict>") -> Scenario:
    """Validate a dict shaped like a scenario file; ScenarioError naming `source` and the field."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: a scenario is a dict (a TOML document), not {type(data).__name__}")
    return parse_scenario(data, source)


def as_scenario(scenario: Scenario | dict | str | Path | Builder) -> Scenario:
    """A Scenario from a Scenario, a dict (`from_dict`), a file path (`load`) or a `Builder`."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, Builder):
        return scenario.build()
    if isinstance(scenario, dict):
        return from_dict(scenario)
    if isinstance(scenario, (str, Path)):
        return load(scenario)
    raise TypeError(f"a scenario is a Scenario, a dict, a file path or a Builder, not {type(scenario).__name__}")


def source_of(scenario: Any) -> str:
    """How messages name a scenario: its file, else its name."""
    if isinstance(scenario, (str, Path)):
        return str(scenario)
    name = getattr(scenario, "name", "") or ""
    return f"<scenario {name}>" if name else "<scenario>"


def with_duration(s: Scenario, duration: float | None, source: str = "<scenario>") -> None:
    """Check a duration override as `--duration` is checked (finite, at least one step, a
    recording that fits in memory); ScenarioError otherwise."""
    if duration is None:
        return
    if isinstance(duration, bool) or not isinstance(duration, (int, float)):
        raise ScenarioError(f"{source}: duration must be a number of seconds, not {duration!r}")
    parse_scenario(
        {**s.model_dump(), "run": {**s.run.model_dump(), "duration": duration}}, f"{source} with duration {duration:g}"
    )


class Builder:
    """A scenario made in code. Keyword arguments of the constructor go to their table:
    run (dt, duration, clock, seed, on_dropout, lockstep_deadline, max_added_agents),
    gains (c1, c2, law), sensing (range, fov, selection, hysteresis); `target=(x, y)`.

        b = Builder("demo", dt=0.05, duration=20.0, c1=1.0, c2=0.5)
        b.leader(1, x=2, y=0, heading=1.57, speed=1.0, orbit_radius=2.0)
        b.follower(2, x=0, y=-3, heading=0.0, speed=1.5)
        b.safety(0.3, arena=[-5, -5, 5, 5])  # optional: the safety filter
        scenario = b.build()
    """

    def __init__(
        self, name: str = "", *, description: str = "", target: tuple[float, float] | None = None, **fields: Any
    ):
        self.data: dict[str, Any] = {"name": name}
        if description:
            self.data["description"] = description
        if target is not None:
            x, y = target
            self.data["target"] = {"x": x, "y": y}
        for key, value in fields.items():
            table = next((t for t, spec in _TABLES.items() if key in spec.model_fields), None)
            if table is None:
                known = sorted(k for spec in _TABLES.values() for k in spec.model_fields)
                raise TypeError(f"Builder: unknown setting {key!r} (known: {', '.join(known)}, target, description)")
            self.data.setdefault(table, {})[key] = value
        self.data["agents"] = []
        self.data["faults"] = []

    def agent(self, **fields: Any) -> Builder:
        """One [[agents]] entry, its fields as in a file (id, role, x, y, heading, speed, ...)."""
        self.data["agents"].append(dict(fields))
        return self

    def leader(
        self, id: int, x: float, y: float, heading: float, speed: float, orbit_radius: float, **more: Any
    ) -> Builder:
        """A leader (more: direction = "ccw" | "cw", max_turn_rate)."""
        return self.agent(
            id=id, role="leader", x=x, y=y, heading=heading, speed=speed, orbit_radius=orbit_radius, **more
        )

    def follower(self, id: int, x: float, y: float, heading: float, speed: float, **more: Any) -> Builder:
        """A follower (more: follow, max_turn_rate)."""
        return self.agent(id=id, role="follower", x=x, y=y, heading=heading, speed=speed, **more)

    def fault(self, at: float, kind: str, agent: int | None = None, **more: Any) -> Builder:
        """A scripted fault (more: duration, probability, what, delay, std)."""
        entry = {"at": at, "kind": kind, **more}
        if agent is not None:
            entry["agent"] = agent
        self.data["faults"].append(entry)
        return self

    def safety(self, radius: float, **more: Any) -> Builder:
        """The [safety] table: the safety filter and its figures (more: arena, lookahead,
        gamma, speed, enabled; docs/guides/scenarios.md#safety)."""
        self.data["safety"] = {"radius": radius, **more}
        return self

    def to_dict(self) -> dict:
        """The scenario as a dict of the file's shape (a copy)."""
        return json.loads(json.dumps(self.data, default=_plain))

    def build(self) -> Scenario:
        """The validated scenario; ScenarioError naming the field otherwise."""
        return from_dict(self.to_dict(), f"<builder {self.data['name']}>" if self.data["name"] else "<builder>")


def _plain(o: Any) -> Any:
    """numpy scalars (and anything else with `.item()`) as plain Python numbers."""
    if hasattr(o, "item"):
        return o.item()
    raise TypeError(f"not a scenario value: {o!r}")


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):  # a JSON string without \u escapes above ASCII is a TOML basic string
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def _key(k: str) -> str:
    """A TOML key: bare when it can be, else quoted (e.g. a [law.params] name with a space or a dot)."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k, ensure_ascii=False)


def _table(name: str, data: dict, lines: list[str]) -> None:
    """`data` as TOML under `name` ("" at the top): its values, then its tables, then its
    arrays of tables."""
    subs = {k: v for k, v in data.items() if isinstance(v, dict)}
    arrays = {k: v for k, v in data.items() if isinstance(v, list) and v and all(isinstance(x, dict) for x in v)}
    if name:
        lines += ["", f"[{name}]"]
    lines += [f"{_key(k)} = {_value(v)}" for k, v in data.items() if k not in subs and k not in arrays]
    for k, v in subs.items():
        _table(f"{name}.{_key(k)}" if name else _key(k), v, lines)
    for k, items in arrays.items():
        for item in items:
            lines += ["", f"[[{name}.{k}]]" if name else f"[[{k}]]"]
            lines += [f"{_key(kk)} = {_value(x)}" for kk, x in item.items()]


def to_toml(scenario: Scenario) -> str:
    """The scenario as a TOML file (what differs from the defaults) that loads back to an
    equal scenario."""
    lines: list[str] = []
    _table("", scenario.model_dump(exclude_defaults=True, exclude_none=True), lines)
    text = "\n".join(lines) + "\n"
    back = parse_scenario(tomllib.loads(text), "<to_toml>")
    if back != scenario:  # a value TOML cannot carry as it is: never hand a process another scenario
        raise ValueError("to_toml: the scenario does not survive a round trip through TOML")
    return text
