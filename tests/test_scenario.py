"""swarm.contracts.scenario: valid files load; every bad input is rejected naming the file and field,
through load_scenario and through `swarm check` (exit 2, no traceback)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from swarm.cli import app
from swarm.contracts.scenario import Scenario, ScenarioError, load_scenario, parse_scenario

SCENARIOS = sorted((Path(__file__).resolve().parent.parent / "scenarios").glob("*.toml"))


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
    ("follower-only-cycle", _all(_set("agents.1.follow", 3), _set("agents.2.follow", 2)),
     ["agents", "cycle", "2 -> 3 -> 2"]),
    ("fixed-without-follow", _set("agents.2.follow", _DELETE), ["agents[2].follow", "fixed"]),
    # v / max_turn_rate = 1.0 / 0.25 = 4 m > R = 2 m
    ("unreachable-orbit", _set("agents.0.max_turn_rate", 0.25), ["agents[0].orbit_radius", "not reachable"]),
    ("no-agents", _set("agents", []), ["agents"]),
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


@pytest.mark.parametrize("mutate, fragments", [pytest.param(m, f, id=i) for i, m, f in BAD])
def test_bad_input_rejected_by_cli_check(base, write_toml, mutate, fragments):
    mutate(base)
    path = write_toml(base, "bad.toml")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == 2, res.output
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
    assert res.exit_code == 2
    assert str(path) in res.stderr and "TOML syntax error" in res.stderr
    assert "Traceback" not in res.output


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ScenarioError, match="no such file") as exc:
        load_scenario(path)
    assert str(path) in str(exc.value)
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == 2
    assert str(path) in res.stderr and "no such file" in res.stderr
    assert "Traceback" not in res.output


def test_directory_instead_of_file(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path)
    res = CliRunner().invoke(app, ["check", str(tmp_path)])
    assert res.exit_code == 2 and "Traceback" not in res.output


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
    with pytest.raises(Exception):
        s.run.dt = 1.0  # type: ignore[misc]
    with pytest.raises(Exception):
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
    [pytest.param(("agents", 1, "speed"), "1.5", id="string-speed"),
     pytest.param(("agents", 1, "x"), True, id="bool-x")],
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
