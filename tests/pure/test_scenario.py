"""swarm.contracts.scenario: valid files load; every bad input is rejected naming the file and field,
through load_scenario and through `swarm check` (exit 2, no traceback)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from pydantic import ValidationError
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts import scenario as scenario_module
from swarm.contracts.scenario import Scenario, ScenarioError, load_scenario, parse_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.contracts.wire import MAX_AGENT_ID, MAX_AGENTS

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


def _set(path: str, value):
    """Mutation setting a dotted path, e.g. 'agents.1.speed' (list indices as ints)."""

    def mutate(d: dict) -> None:
        *parents, last = path.split(".")
        cur = d
        for p in parents:
            cur = cur[int(p)] if isinstance(cur, list) else cur[p]
        if value is _DELETE:
            if isinstance(cur, list):
                del cur[int(last)]
            else:
                del cur[last]
        elif isinstance(cur, list):
            cur[int(last)] = value
        else:
            cur[last] = value

    return mutate


_DELETE = object()


def _all(*mutations):
    def mutate(d: dict) -> None:
        for m in mutations:
            m(d)

    return mutate


def _no_leader(d: dict) -> None:
    lead = d["agents"][0]
    lead.update(role="follower", follow=3)
    del lead["orbit_radius"]


# (case id, mutation of the base dict, fragments that must all appear in the message)
BAD = [
    ("unknown-top-level", _set("colour", "red"), ["colour", "unknown key"]),
    ("unknown-in-run", _set("run.colour", "red"), ["run.colour", "unknown key"]),
    ("unknown-in-agent", _set("agents.0.colour", "red"), ["agents[0].colour", "unknown key"]),
    ("unknown-in-gains", _set("gains.c3", 1.0), ["gains.c3", "unknown key"]),
    ("wrong-type-speed", _set("agents.1.speed", "fast"), ["agents[1].speed"]),
    ("wrong-type-selection", _set("sensing.selection", "random"), ["sensing.selection"]),
    ("zero-speed", _set("agents.1.speed", 0.0), ["agents[1].speed", "greater than 0"]),
    ("negative-speed", _set("agents.2.speed", -1.0), ["agents[2].speed", "greater than 0"]),
    ("nan-speed", _set("agents.1.speed", math.nan), ["agents[1].speed", "finite"]),
    ("zero-radius", _set("agents.0.orbit_radius", 0.0), ["agents[0].orbit_radius"]),
    ("negative-radius", _set("agents.0.orbit_radius", -2.0), ["agents[0].orbit_radius"]),
    ("zero-dt", _set("run.dt", 0.0), ["run.dt", "greater than 0"]),
    ("negative-dt", _set("run.dt", -0.01), ["run.dt"]),
    ("zero-gain", _set("gains.c2", 0.0), ["gains.c2"]),
    ("fov-over-2pi", _set("sensing.fov", 7.0), ["sensing.fov"]),
    ("hysteresis-1", _set("sensing.hysteresis", 1.0), ["sensing.hysteresis"]),
    ("missing-gains", _set("gains", _DELETE), ["gains", "required"]),
    ("missing-speed", _set("agents.2.speed", _DELETE), ["agents[2].speed", "required"]),
    ("duplicate-ids", _set("agents.2.id", 1), ["agents", "duplicate agent id 1"]),
    ("no-leader", _no_leader, ["agents", "leader"]),
    ("leader-without-radius", _set("agents.0.orbit_radius", _DELETE), ["agents[0].orbit_radius"]),
    ("follower-with-radius", _set("agents.1.orbit_radius", 3.0), ["agents[1].orbit_radius"]),
    ("follow-missing-agent", _set("agents.1.follow", 99), ["agents[1].follow", "99"]),
    ("follow-self", _set("agents.1.follow", 2), ["agents[1].follow", "itself"]),
    ("follow-on-leader", _set("agents.0.follow", 2), ["agents[0].follow"]),
    (
        "follower-only-cycle",
        _all(_set("agents.1.follow", 3), _set("agents.2.follow", 2)),
        ["agents", "cycle", "2 -> 3 -> 2"],
    ),
    ("fixed-without-follow", _set("agents.2.follow", _DELETE), ["agents[2].follow", "fixed"]),
    # v / max_turn_rate = 1.0 / 0.25 = 4 m > R = 2 m
    ("unreachable-orbit", _set("agents.0.max_turn_rate", 0.25), ["agents[0].orbit_radius", "not reachable"]),
    ("no-agents", _set("agents", []), ["agents"]),
    # values that validate one by one but cannot run (base: 3 agents, dt 0.05 s, 10 s)
    ("inf-duration", _set("run.duration", math.inf), ["run.duration", "finite"]),
    ("nan-duration", _set("run.duration", math.nan), ["run.duration", "finite"]),
    ("inf-dt", _set("run.dt", math.inf), ["run.dt", "finite"]),
    ("nan-dt", _set("run.dt", math.nan), ["run.dt", "finite"]),
    (
        "huge-duration",
        _set("run.duration", 1e300),
        ["run.duration", "2e+301 steps", "2e8 agent-ticks", "shorter run.duration or a larger run.dt"],
    ),
    (
        "steps-overflow",
        _all(_set("run.duration", 1e300), _set("run.dt", 1e-300)),
        ["run.duration", "inf steps", "larger run.dt"],
    ),
    ("duration-under-half-a-step", _set("run.duration", 0.02), ["run.duration", "shorter than one step (dt = 0.05 s)"]),
    # 1e8 ticks x (3 + 12) agents
    (
        "recording-too-large",
        _all(_set("run.dt", 0.001), _set("run.duration", 1e5)),
        ["run.duration", "100000000 ticks x 15 agents", "1.5e+09 agent-ticks", "2e8", "larger run.dt"],
    ),
    (
        "added-agents-over-wire",
        _set("run.max_added_agents", 9998),
        ["run.max_added_agents", "10001 agents", "wire carries (10000)", "9997 or fewer"],
    ),
    ("added-agents-above-limit", _set("run.max_added_agents", 10**6), ["run.max_added_agents", "10000"]),
    ("negative-added-agents", _set("run.max_added_agents", -1), ["run.max_added_agents"]),
    (
        "added-ids-past-wire",
        lambda d: (d["run"].update(max_added_agents=12), d["agents"][2].update(id=2**31 - 5)),
        ["agents[2].id", "2147483644..2147483655", "2147483647", "run.max_added_agents = 4 or fewer"],
    ),
    ("negative-id", _set("agents.2.id", -3), ["agents[2].id", "greater than or equal to 0"]),
    ("huge-id", _set("agents.2.id", 10**400), ["agents[2].id", "2147483647"]),
    ("huge-follow", _set("agents.2.follow", 10**400), ["agents[2].follow", "2147483647"]),
    (
        "huge-fault-agent",
        _set("faults", [{"at": 1.0, "kind": "kill", "agent": 10**400}]),
        ["faults[0].agent", "2147483647"],
    ),
    ("negative-seed", _set("run.seed", -1), ["run.seed", "greater than or equal to 0"]),
    ("huge-seed", _set("run.seed", 10**400), ["run.seed", "less than or equal to"]),
    ("relative-law-module", _set("gains.law", ".nowhere:law"), ["gains.law", "cannot import"]),
    # finite values the engine cannot honour (docs/guides/scenarios.md#checks): overflow, no precision left, no end
    ("huge-x", _set("agents.0.x", 1e308), ["agents[0].x", "less than or equal to 10000000"]),
    ("huge-target", _set("target.y", -1e12), ["target.y", "greater than or equal to -10000000"]),
    ("huge-heading", _set("agents.1.heading", 1e17), ["agents[1].heading", "1000000"]),
    ("huge-speed", _set("agents.1.speed", 1e200), ["agents[1].speed", "100000"]),
    ("huge-radius", _set("agents.0.orbit_radius", 1e300), ["agents[0].orbit_radius", "10000000"]),
    ("huge-gain", _set("gains.c1", 1e300), ["gains.c1", "1000000"]),
    ("huge-range", _set("sensing.range", 1e300), ["sensing.range", "10000000"]),
    ("huge-deadline", _set("run.lockstep_deadline", 1e300), ["run.lockstep_deadline", "3600"]),
]


@pytest.mark.parametrize("mutate, fragments", [pytest.param(m, f, id=i) for i, m, f in BAD])
def test_bad_input_rejected_by_load_scenario(base, write_toml, mutate, fragments):
    mutate(base)
    path = write_toml(base, "bad.toml")
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    msg = str(exc.value)
    assert str(path) in msg
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"


@pytest.mark.slow
@pytest.mark.parametrize("mutate, fragments", [pytest.param(m, f, id=i) for i, m, f in BAD])
def test_bad_input_rejected_by_cli_check(base, write_toml, mutate, fragments):
    mutate(base)
    path = write_toml(base, "bad.toml")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == ExitCode.USAGE, res.output
    assert isinstance(res.exception, SystemExit)
    assert "Traceback" not in res.output
    assert str(path) in res.stderr
    for frag in fragments:
        assert frag in res.stderr, f"{frag!r} not in {res.stderr!r}"
    assert "ok" not in res.stdout


def test_toml_syntax_error_names_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[run\ndt = 0.01\n")
    with pytest.raises(ScenarioError, match="TOML syntax error") as exc:
        load_scenario(path)
    assert str(path) in str(exc.value)
    assert "line 1" in str(exc.value)
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == ExitCode.USAGE
    assert str(path) in res.stderr and "TOML syntax error" in res.stderr
    assert "Traceback" not in res.output


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ScenarioError, match="no such file") as exc:
        load_scenario(path)
    assert str(path) in str(exc.value)
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == ExitCode.USAGE
    assert str(path) in res.stderr and "no such file" in res.stderr
    assert "Traceback" not in res.output


def test_directory_instead_of_file(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path)
    res = CliRunner().invoke(app, ["check", str(tmp_path)])
    assert res.exit_code == ExitCode.USAGE and "Traceback" not in res.output


def test_error_message_is_one_line_per_problem(base, write_toml):
    base["agents"][1]["speed"] = "fast"
    base["run"]["colour"] = 1
    path = write_toml(base)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    lines = str(exc.value).splitlines()
    assert lines[0] == f"{path}: invalid scenario"
    assert len(lines) == 3
    assert any(line.strip().startswith("run.colour:") for line in lines[1:])
    assert any(line.strip().startswith("agents[1].speed:") for line in lines[1:])


def test_parse_scenario_names_source(base):
    base["run"]["dt"] = 0
    with pytest.raises(ScenarioError, match=r"^my-source: invalid scenario\n  run\.dt:"):
        parse_scenario(base, "my-source")


# -- valid input ----------------------------------------------------------------------


def test_base_loads_with_defaults(base, write_toml):
    s = load_scenario(write_toml(base))
    assert isinstance(s, Scenario)
    assert s.ids == [1, 2, 3]
    assert s.run.ticks == 200  # 10 s / 0.05 s
    assert s.run.clock == "lockstep" and s.run.on_dropout == "leave"
    assert s.gains.law == "bearing"
    assert s.sensing.range is None and s.sensing.fov is None and s.sensing.hysteresis == 0.0
    assert s.agent(1).direction == "ccw" and s.agent(1).direction_sign == 1
    assert s.agent(2).follow == 1 and s.agent(2).max_turn_rate is None
    with pytest.raises(KeyError):
        s.agent(42)


def test_models_are_frozen(base):
    s = parse_scenario(base)
    with pytest.raises(ValidationError):
        s.run.dt = 1.0  # type: ignore[misc]
    with pytest.raises(ValidationError):
        s.agents[0].speed = 3.0  # type: ignore[misc]


def test_cw_direction_sign(base):
    base["agents"][0]["direction"] = "cw"
    assert parse_scenario(base).agent(1).direction_sign == -1


def test_reachable_orbit_at_the_limit(base):
    # R == v / max_turn_rate exactly is reachable
    base["agents"][0]["max_turn_rate"] = 0.5
    assert parse_scenario(base).agent(1).max_turn_rate == 0.5


def test_cycle_allowed_with_nearest_selection(base):
    # `follow` only pins the graph with selection = "fixed"; nearest ignores it
    base["sensing"]["selection"] = "nearest"
    base["agents"][1]["follow"] = 3
    base["agents"][2]["follow"] = 2
    parse_scenario(base)
    del base["agents"][2]["follow"]
    parse_scenario(base)


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_load(path):
    s = load_scenario(path)
    assert s.name == path.stem
    assert any(a.role == "leader" for a in s.agents)


@pytest.mark.parametrize(
    "where, value",
    [
        pytest.param(("agents", 1, "speed"), "1.5", id="string-speed"),
        pytest.param(("agents", 1, "x"), True, id="bool-x"),
    ],
)
def test_wrong_toml_type_is_rejected_not_coerced(base, write_toml, where, value):
    base[where[0]][where[1]][where[2]] = value
    path = write_toml(base)
    with pytest.raises(ScenarioError, match=r"agents\[1\]\." + where[2]):
        load_scenario(path)


def test_toml_writer_round_trips(base, write_toml):
    # the conftest writer is what every bad-input case relies on
    with open(write_toml(base), "rb") as f:
        assert tomllib.load(f) == base


# -- added agents, and what the wire and the recording can hold -------------------------


def test_added_agents_default_to_four_per_scenario_agent(base):
    s = parse_scenario(base)
    assert s.run.max_added_agents is None
    assert s.added_agents_cap == 12
    assert s.added_id_range == range(4, 16)


def test_added_agents_set_explicitly(base):
    base["agents"][2]["id"] = 30
    base["run"]["max_added_agents"] = 5
    s = parse_scenario(base)
    assert s.added_agents_cap == 5
    assert s.added_id_range == range(31, 36)


def test_no_added_agents_allows_the_largest_id(base):
    base["run"]["max_added_agents"] = 0
    base["agents"][2]["id"] = MAX_AGENT_ID
    s = parse_scenario(base)
    assert s.added_agents_cap == 0 and len(s.added_id_range) == 0


def test_added_ids_up_to_the_largest_wire_id(base):
    base["agents"][2]["id"] = MAX_AGENT_ID - 12
    assert parse_scenario(base).added_id_range[-1] == MAX_AGENT_ID


def _leaders(n: int) -> list[dict]:
    return [
        {"id": i, "role": "leader", "x": float(i), "y": 0.0, "heading": 0.0, "speed": 1.0, "orbit_radius": 2.0}
        for i in range(n)
    ]


def test_more_agents_than_the_wire_carries(base):
    base["agents"] = _leaders(MAX_AGENTS + 1)
    with pytest.raises(ScenarioError, match=r"\n  agents: 10001 agents, more than the wire carries \(10000\)$"):
        parse_scenario(base, "big.toml")


def test_default_added_agents_stay_within_the_wire(base):
    # 2001 agents: the default (4 x) would pass 10,000 agents, so it stops at what the wire carries
    base["agents"] = _leaders(2001)
    assert parse_scenario(base, "many.toml").added_agents_cap == 10_000 - 2001
    # ... and below the largest id the wire carries
    base["agents"] = _leaders(3)
    base["agents"][2]["id"] = 2**31 - 5
    assert parse_scenario(base).added_agents_cap == 4
    # set by hand, past the wire: refused, with what to set instead
    base["agents"] = _leaders(2001)
    base["run"]["max_added_agents"] = 8004
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(base, "many.toml")
    msg = str(exc.value)
    assert "run.max_added_agents: 10005 agents (2001 + 8004 that may be added)" in msg
    assert "set run.max_added_agents = 7999 or fewer" in msg


def test_recording_limit_counts_added_agents(base):
    # 1e6 ticks x 15 agents = 1.5e7: fine; x 300 agents = 3e8: too much
    base["run"].update(dt=0.01, duration=1e4)
    assert parse_scenario(base).run.ticks == 10**6
    base["run"]["max_added_agents"] = 297
    with pytest.raises(ScenarioError, match=r"run\.duration: .*3e\+08 agent-ticks.*max_added_agents lower"):
        parse_scenario(base)


def test_inf_duration_in_toml_is_rejected(base, write_toml):
    path = write_toml(base)
    path.write_text(path.read_text().replace("duration = 10.0", "duration = inf"))
    assert "duration = inf\n" in path.read_text()  # the TOML literal, as a user writes it
    with pytest.raises(ScenarioError, match=r"run\.duration: Input should be a finite number"):
        load_scenario(path)


def test_schema_describes_max_added_agents():
    prop = Scenario.model_json_schema()["$defs"]["RunSpec"]["properties"]["max_added_agents"]
    assert prop["description"] == (
        "agents that may be added while the run goes (swarm spawn of a new id); default 4 x the scenario's agents"
    )


# -- files that are not scenarios: always a ScenarioError naming the file --------------


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("a = " + "[" * 100_000 + "]" * 100_000, id="deep-arrays"),
        pytest.param("a = " + "{b = " * 5_000 + "1" + "}" * 5_000, id="deep-inline-tables"),
        pytest.param("gains = " + "[" * 600 + "]" * 600, id="deep-in-a-field"),
    ],
)
def test_nested_too_deeply(tmp_path, text):
    path = tmp_path / "deep.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    assert str(exc.value) == f"{path}: nested too deeply (arrays or tables inside one another)"


@pytest.mark.parametrize(
    "raw, fragment",
    [
        pytest.param(bytes(range(256)) * 4, "not UTF-8 text", id="binary"),
        pytest.param(b'name = "\xff\xfe"\n', "not UTF-8 text (byte 8", id="latin-1"),
        pytest.param(b"\x00\x00\x00", "TOML syntax error", id="nul-bytes"),
        pytest.param(b"", "gains: Field required", id="empty"),
        pytest.param(
            b"[run]\nseed = " + b"9" * 5000 + b"\n",
            "cannot parse: Exceeds the limit (4300 digits)",
            id="5000-digit-integer",
        ),
    ],
)
def test_not_a_scenario_file(tmp_path, raw, fragment):
    path = tmp_path / "odd.toml"
    path.write_bytes(raw)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    assert str(exc.value).startswith(f"{path}: ")
    assert fragment in str(exc.value)


def test_file_larger_than_the_limit(tmp_path, monkeypatch, base, write_toml):
    path = write_toml(base)
    monkeypatch.setattr(scenario_module, "MAX_SCENARIO_BYTES", path.stat().st_size - 1)
    with pytest.raises(ScenarioError, match=r"larger than .* MiB; not a scenario file"):
        load_scenario(path)


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_endless_file_is_read_bounded(monkeypatch):
    monkeypatch.setattr(scenario_module, "MAX_SCENARIO_BYTES", 1 << 16)
    with pytest.raises(ScenarioError, match=r"^/dev/zero: larger than"):
        load_scenario("/dev/zero")


def test_byte_order_mark_and_crlf_are_read(base, write_toml):
    path = write_toml(base)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\n", b"\r\n"))
    assert parse_scenario(base) == load_scenario(path)


# -- [sensing.tuning] (swarm/contracts/tuning.py) ----------------------------------------------------

_TWO = {
    "gains": {"c1": 1.0, "c2": 0.5},
    "agents": [
        {"id": 1, "role": "leader", "x": 0, "y": 0, "heading": 0, "speed": 1, "orbit_radius": 1},
        {"id": 2, "role": "follower", "x": 5, "y": 0, "heading": 0, "speed": 1},
    ],
}


def test_tuning_defaults_are_the_shipped_values():
    from swarm.contracts.tuning import SelectionTuning, TuningTicks

    t = parse_scenario(_TWO).sensing.tuning
    assert t == SelectionTuning()
    assert (t.hold_s, t.coast_s, t.reach, t.edge, t.search_pitch) == (5.0, 5.0, 0.85, 0.8, 0.5)
    assert (t.search_first_out, t.search_growth) == (4.0, 2.0)
    # hold used to be max(20 ticks, coast ticks): the same at dt <= 0.25 s
    for dt in (0.01, 0.05, 0.1, 0.25):
        k = TuningTicks.of(t, dt)
        assert k.hold == k.coast == max(20, math.ceil(5.0 / dt - 1e-9))
    assert TuningTicks.of(SelectionTuning(hold_s=0.001), 0.05).hold == 1  # at least one tick


def test_tuning_table_is_read_and_checked_naming_the_field():
    s = parse_scenario({**_TWO, "sensing": {"tuning": {"hold_s": 3, "reach": 0.7}}})
    assert (s.sensing.tuning.hold_s, s.sensing.tuning.reach, s.sensing.tuning.coast_s) == (3.0, 0.7, 5.0)
    for bad, field, words in [
        ({"hold_s": -1.0}, "sensing.tuning.hold_s", "greater than 0"),
        ({"reach": 1.5}, "sensing.tuning.reach", "less than or equal to 1"),
        ({"edge": 0}, "sensing.tuning.edge", "greater than 0"),
        ({"search_growth": 1.0}, "sensing.tuning.search_growth", "greater than 1"),
        ({"hold": 5.0}, "sensing.tuning.hold", "unknown key"),
        ({"coast_s": "5"}, "sensing.tuning.coast_s", "number"),
    ]:
        with pytest.raises(ScenarioError) as e:
            parse_scenario({**_TWO, "sensing": {"tuning": bad}}, "t.toml")
        assert field in str(e.value) and words in str(e.value) and "t.toml" in str(e.value)


def test_tuning_overlay_of_a_dump_validates():
    """What `swarm study scenario --param tuning.FIELD=...` does: set sensing.tuning.FIELD in a
    dump of the scenario and validate it again."""
    s = parse_scenario(_TWO)
    d = s.model_dump()
    d["sensing"]["tuning"]["coast_s"] = 2.5
    assert Scenario.model_validate(d).sensing.tuning.coast_s == 2.5
    d["sensing"]["tuning"]["coast_s"] = 0.0
    with pytest.raises(ValidationError, match="coast_s"):
        Scenario.model_validate(d)


def test_tuning_travels_to_agent_processes():
    import json

    from swarm.contracts.brain_config import BrainConf

    s = parse_scenario({**_TWO, "sensing": {"range": 40.0, "tuning": {"coast_s": 2.0, "edge": 0.9}}})
    conf = BrainConf.from_scenario(s, 2)
    back = BrainConf.from_json(json.loads(json.dumps(conf.to_json())))
    assert back == conf and back.sensing.tuning._asdict() == s.sensing.tuning.model_dump()
    d = conf.to_json()
    del d["sensing"]["tuning"]  # an older world: the defaults
    assert BrainConf.from_json(d).sensing.tuning._asdict() == parse_scenario(_TWO).sensing.tuning.model_dump()
    d["sensing"]["tuning"] = {"edge": 2.0}
    with pytest.raises(ValueError, match=r"sensing\.tuning\.edge"):
        BrainConf.from_json(d)


def test_the_agents_plain_tuning_is_the_scenarios_with_the_same_defaults():
    """BrainConf carries TuningValues (no pydantic in agent processes): the same fields and
    defaults as the scenario's SelectionTuning, and a join reply's table checked by field."""
    from swarm.contracts.tuning import SelectionTuning
    from swarm.contracts.tuning_ticks import TuningValues, tuning_values

    assert TuningValues._fields == tuple(SelectionTuning.model_fields)
    assert TuningValues() == TuningValues(**SelectionTuning().model_dump())
    for name, field in SelectionTuning.model_fields.items():  # the same bounds
        from swarm.contracts.tuning_ticks import LIMITS

        low, high = LIMITS[name]
        gt = next(m.gt for m in field.metadata if hasattr(m, "gt"))
        le = next(m.le for m in field.metadata if hasattr(m, "le"))
        assert (gt, le) == (low, high), name
    assert tuning_values({"coast_s": 2}) == TuningValues(coast_s=2.0)
    for bad, field in (({"coast": 1.0}, "sensing.tuning.coast"), ({"hold_s": -1.0}, "sensing.tuning.hold_s")):
        with pytest.raises(ValueError, match=field):
            tuning_values(bad)
