"""Scenario files: TOML read into strict, frozen pydantic models.

`Scenario` is a whole file: its tables (swarm/contracts/scenario_tables.py, each checked
on its own) and what must hold across them. `load_scenario(path)` is the one entry point;
every problem with a file comes out of it as a `ScenarioError` whose message names the
file and the field. That includes values that validate one by one but cannot run
together: more agents than the wire carries, ids past its largest id, a recording too
large for memory (see `Scenario._limits`).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, ValidationInfo, field_validator, model_validator

from swarm.contracts.scenario_tables import (
    MAX_AGENT_TICKS,
    RECORDING_LIMIT,
    AgentSpec,
    FaultSpec,
    GainsSpec,
    LawSpec,
    RunSpec,
    SafetySpec,
    SensingSpec,
    Strict,
    TargetSpec,
)
from swarm.contracts.vocabulary import Coded, ExitCode
from swarm.contracts.wire import MAX_AGENT_ID, MAX_AGENTS

MAX_SCENARIO_BYTES = 32 << 20  # a 10,000-agent scenario is about 1.5 MB


class Scenario(Strict):
    """A whole scenario file."""

    name: str = Field(default="", description="free-text name")
    description: str = Field(default="", description="free text: where the numbers come from")
    run: RunSpec = RunSpec()
    target: TargetSpec = TargetSpec()
    gains: GainsSpec
    # built unvalidated: checking the built-in laws here would import agent code with this module
    law: LawSpec = LawSpec.model_construct()
    sensing: SensingSpec = SensingSpec()
    agents: list[AgentSpec] = Field(min_length=1)
    faults: list[FaultSpec] = Field(default_factory=list, description="scripted faults, by time")
    safety: SafetySpec | None = Field(
        default=None, description="the safety filter and its figures (docs/design/safety.md); none: neither"
    )

    @field_validator("agents", mode="before")
    @classmethod
    def _not_too_many(cls, agents: Any) -> Any:
        # before validating each one: a file of a million agents fails at once
        if isinstance(agents, list) and len(agents) > MAX_AGENTS:
            raise ValueError(f"{len(agents)} agents, more than the wire carries ({MAX_AGENTS})")
        return agents

    @field_validator("agents")
    @classmethod
    def _unique_ids(cls, agents: list[AgentSpec]) -> list[AgentSpec]:
        seen: dict[int, int] = {}
        for k, a in enumerate(agents):
            if a.id in seen:
                raise ValueError(f"agents[{k}].id: duplicate agent id {a.id} (also agents[{seen[a.id]}])")
            seen[a.id] = k
        return agents

    @model_validator(mode="after")
    def _graph(self) -> Scenario:
        ids = {a.id for a in self.agents}
        if not any(a.role == "leader" for a in self.agents):
            raise ValueError('agents: at least one agent must have role = "leader"')
        for k, a in enumerate(self.agents):
            if a.follow is not None:
                if a.follow not in ids:
                    raise ValueError(f"agents[{k}].follow: no agent has id {a.follow}")
                if a.follow == a.id:
                    raise ValueError(f"agents[{k}].follow: an agent cannot follow itself")
        for k, f in enumerate(self.faults):
            if f.agent is not None and f.agent not in ids:
                raise ValueError(f"faults[{k}].agent: no agent has id {f.agent}")
        if self.sensing.selection == "fixed":
            by_id = {a.id: a for a in self.agents}
            for k, a in enumerate(self.agents):
                if a.role == "follower" and a.follow is None:
                    raise ValueError(f'agents[{k}].follow: selection = "fixed" needs `follow` on every follower')
            for k, a in enumerate(self.agents):
                seen = [a.id]
                cur = a
                while cur.role == "follower" and cur.follow is not None:
                    cur = by_id[cur.follow]
                    if cur.id in seen:
                        cycle = " -> ".join(str(i) for i in seen[seen.index(cur.id) :] + [cur.id])
                        raise ValueError(f"agents[{k}].follow: follower-only cycle in the fixed graph: {cycle}")
                    seen.append(cur.id)
        return self

    @model_validator(mode="after")
    def _in_the_arena(self, info: ValidationInfo) -> Scenario:
        # not for a scenario read back from a recording (context check_laws = False): it ran as it
        # was (in robots mode with a robots file's arena, whatever the scenario's starts)
        if self.safety is not None and (info.context or {}).get("check_laws", True):
            for k, a in enumerate(self.agents):
                if not self.safety.inside(a.x, a.y):
                    raise ValueError(f"agents[{k}]: agent {a.id} starts at ({a.x:g}, {a.y:g}), outside safety.arena")
        return self

    @model_validator(mode="after")
    def _one_follower_law(self) -> Scenario:
        if self.gains.law != "bearing" and self.law.follower != "bearing":
            raise ValueError(
                f"law.follower: the follower law is named twice ([gains] law = {self.gains.law!r}, the "
                f"older (g_i, g_j, lambda_ij, c1, c2) signature, and [law] follower = {self.law.follower!r}): "
                "keep one"
            )
        return self

    @model_validator(mode="after")
    def _limits(self) -> Scenario:
        """What the wire and the recording can hold, counting the agents that may be added."""
        n, cap = len(self.agents), self.added_agents_cap
        default = " (the default, 4 x agents)" if self.run.max_added_agents is None else ""
        if n + cap > MAX_AGENTS:
            raise ValueError(
                f"run.max_added_agents: {n + cap} agents ({n} + {cap} that may be added{default}), more "
                f"than the wire carries ({MAX_AGENTS}); set run.max_added_agents = {_at_most(MAX_AGENTS - n)}"
            )
        top = max(self.ids)
        if cap and top + cap > MAX_AGENT_ID:
            raise ValueError(
                f"agents[{self.ids.index(top)}].id: the {cap} agents that may be added{default} take ids "
                f"{top + 1}..{top + cap}, past the largest id the wire carries ({MAX_AGENT_ID}); use "
                f"smaller ids or set run.max_added_agents = {_at_most(MAX_AGENT_ID - top)}"
            )
        ticks = self.run.ticks
        if ticks * (n + cap) > MAX_AGENT_TICKS:
            raise ValueError(
                f"run.duration: the recording would hold {ticks} ticks x {n + cap} agents ({n} + {cap} that "
                f"may be added{default}) = {ticks * (n + cap):.3g} agent-ticks, more than the limit of "
                f"{RECORDING_LIMIT}; use a shorter run.duration or a larger run.dt"
                + (", or set run.max_added_agents lower" if cap else "")
            )
        return self

    def agent(self, agent_id: int) -> AgentSpec:
        for a in self.agents:
            if a.id == agent_id:
                return a
        raise KeyError(agent_id)

    @property
    def law_names(self) -> list[str]:
        """Every law the scenario's agents may import (what `swarm up` tells them to trust)."""
        return list(dict.fromkeys([self.gains.law, self.law.follower, self.law.leader]))

    @property
    def ids(self) -> list[int]:
        return [a.id for a in self.agents]

    @property
    def added_agents_cap(self) -> int:
        """How many agents may be added while the run goes: run.max_added_agents, or by
        default 4 x the scenario's agents (fewer if the wire's limits on the number of agents
        or on ids come first: the default never makes a scenario invalid)."""
        if self.run.max_added_agents is not None:
            return self.run.max_added_agents
        n = len(self.agents)
        top = max((a.id for a in self.agents), default=-1)
        return max(0, min(4 * n, MAX_AGENTS - n, MAX_AGENT_ID - top))

    @property
    def added_id_range(self) -> range:
        """The ids agents added while the run goes may take: right after the largest
        scenario id, `added_agents_cap` of them. Every identity is known before the run
        starts (the hub's access rules need them). Computed from `agents` as they stand: read
        it from the scenario as loaded, not from a copy the world has added agents to."""
        start = max(self.ids) + 1
        return range(start, start + self.added_agents_cap)

    def added_ids_text(self) -> str:
        """The ids agents added while the run goes may take, in words: "ids 7..30", or, when
        there are none, why (run.max_added_agents = 0, no id left past the largest, no room
        on the wire)."""
        ids = self.added_id_range
        if ids:
            return f"ids {ids.start}..{ids.stop - 1}"
        if self.run.max_added_agents == 0:
            return "run.max_added_agents = 0"
        top = max(self.ids)
        if top >= MAX_AGENT_ID:
            return f"agent {top} has the largest id the wire carries, so no id is left after it"
        return f"{len(self.agents)} agents, the most the wire carries ({MAX_AGENTS})"


def _at_most(m: int) -> str:
    return f"{m} or fewer" if m > 0 else f"{m}"


class ScenarioError(Coded):
    """A scenario that cannot be used; the message names the file and the field."""

    exit_code = ExitCode.USAGE


def _loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def format_validation_error(source: str, err: ValidationError, what: str = "scenario") -> str:
    lines = [f"{source}: invalid {what}"]
    for e in err.errors():
        where = _loc(tuple(p for p in e["loc"] if p not in ("function-after",)))
        msg = e["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        m = re.match(r"^([a-z_]+): (.*)$", msg, re.S)
        if m and where:
            where, msg = f"{where}.{m.group(1)}", m.group(2)
        lines.append(f"  {where}: {msg}" if where else f"  {msg}")
    return "\n".join(lines)


_TOO_DEEP = "nested too deeply (arrays or tables inside one another)"


def parse_scenario(data: dict, source: str = "<scenario>", law_dirs: tuple = ()) -> Scenario:
    """Validate an already-parsed TOML document; law modules are also looked for in
    `law_dirs` (appended to sys.path when a law is imported)."""
    try:
        return Scenario.model_validate(data, context={"law_dirs": tuple(str(d) for d in law_dirs)})
    except ValidationError as err:
        raise ScenarioError(format_validation_error(source, err)) from None
    except RecursionError:
        raise ScenarioError(f"{source}: {_TOO_DEEP}") from None
    except MemoryError:
        raise ScenarioError(f"{source}: too large to validate") from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raise ScenarioError naming file and field. The
    file's directory is on the import path of its laws ("module:function")."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            raw = f.read(MAX_SCENARIO_BYTES + 1)  # bounded: /dev/zero or a huge file cannot fill memory
    except FileNotFoundError:
        raise ScenarioError(f"{p}: no such file") from None
    except (OSError, ValueError) as e:  # a directory, no permission, a bad path...
        raise ScenarioError(f"{p}: cannot read: {getattr(e, 'strerror', None) or e}") from None
    if len(raw) > MAX_SCENARIO_BYTES:
        raise ScenarioError(f"{p}: larger than {MAX_SCENARIO_BYTES >> 20} MiB; not a scenario file")
    try:
        # as read_text() would, plus a UTF-8 byte-order mark is allowed
        text = raw.decode("utf-8-sig").replace("\r\n", "\n").replace("\r", "\n")
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{p}: cannot read: not UTF-8 text (byte {e.start}: {e.reason})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{p}: TOML syntax error: {e}") from None
    except ValueError as e:  # e.g. an integer of more than 4300 digits
        raise ScenarioError(f"{p}: cannot parse: {str(e).split(';')[0]}") from None
    except RecursionError:
        raise ScenarioError(f"{p}: {_TOO_DEEP}") from None
    except MemoryError:
        raise ScenarioError(f"{p}: too large to read") from None
    return parse_scenario(data, str(p), (p.resolve().parent,))


def scenario_json_schema() -> dict:
    return Scenario.model_json_schema()
