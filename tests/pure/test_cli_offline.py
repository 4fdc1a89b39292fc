"""The `swarm` CLI without middleware: check, schema, sim (--no-plots), plot, --help."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_invoke import command, invoke
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts.scenario import load_scenario

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))
KEYS = {
    *("ids", "role", "speed", "orbit_radius", "target", "dt", "t", "x", "y", "heading", "u", "out", "alive", "missed"),
    "follow",
}
COMMANDS = ["check", "schema", "sim", "plot", "export"]


@pytest.fixture
def shipped_run(shipped_sim):
    """shipped_run(path) -> (CLI result, out dir): each shipped scenario simulated once, in
    full (shared with the runtime tests: conftest.shipped_sim)."""
    return lambda path: shipped_sim(path.stem)


def test_scenarios_found():
    assert {"case1", "case2", "turtlebot"} <= {p.stem for p in SCENARIOS}


@pytest.mark.slow  # a whole run in-process: the long tier
@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenario_converges_under_sim(path, shipped_run):
    res, out = shipped_run(path)
    assert res.exit_code == 0, res.output
    assert "converged: True" in res.stdout
    summary = json.loads((out / "summary.json").read_text())
    s = load_scenario(path)
    assert summary["converged"] is True
    assert summary["ticks"] == s.run.ticks
    assert summary["scenario"] == s.name
    assert set(summary["agents"]) == {str(i) for i in s.ids}
    # Agents a scripted fault kills for good end dropped; everyone else converges.
    last = {}
    for f in sorted(s.faults, key=lambda f: f.at):
        if f.kind in ("kill", "restart"):
            last[f.agent] = f.kind
    gone = {str(a) for a, kind in last.items() if kind == "kill"}
    for aid, a in summary["agents"].items():
        assert a["alive"] is (aid not in gone), aid
        if aid in gone:
            continue
        assert a["expected_radius"] is not None, aid
        assert a["radial_error"] < 0.01 * a["expected_radius"], (aid, a)
    assert not list(out.glob("*.png"))  # --no-plots
    with np.load(out / "trajectory.npz") as z:
        assert set(z.files) == KEYS
        n = len(s.agents)
        assert z["t"].shape == (s.run.ticks + 1,)
        for k in ("x", "y", "heading", "u", "out", "alive"):
            assert z[k].shape == (s.run.ticks + 1, n), k
        assert z["ids"].tolist() == s.ids
        assert float(z["dt"]) == s.run.dt
        assert z["t"][-1] == pytest.approx(s.run.duration)


@pytest.mark.slow  # a whole run in-process
def test_turtlebot_follower_ends_at_one_metre(shipped_run):
    path = next(p for p in SCENARIOS if p.stem == "turtlebot")
    res, out = shipped_run(path)
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    follower = summary["agents"]["2"]
    assert follower["role"] == "follower"
    assert abs(follower["final_radius"] - 1.000) <= 0.005
    assert follower["expected_radius"] == pytest.approx(1.0, rel=1e-12)
    with np.load(out / "trajectory.npz") as z:
        r = np.hypot(z["x"][-1, 1], z["y"][-1, 1])
        # never faster than the Burger's turn-rate limit
        assert np.nanmax(np.abs(z["u"])) <= 2.84
    assert abs(r - 1.0) <= 0.005


def test_sim_duration_option(tmp_path):
    res = invoke("sim", SCENARIOS[0], "--out", tmp_path, "--no-plots", "--duration", "0.5")
    assert res.exit_code == 0, res.output
    s = load_scenario(SCENARIOS[0])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["ticks"] == int(round(0.5 / s.run.dt))
    assert "wall_time" in summary and summary["engine"] == "sim"


def test_sim_duration_shorter_than_a_step(tmp_path):
    res = invoke("sim", SCENARIOS[0], "--out", tmp_path, "--no-plots", "--duration", "0.001")
    assert res.exit_code == 2
    assert "shorter than one step" in res.stderr
    assert not (tmp_path / "summary.json").exists()


def test_sim_on_bad_file_exits_2_without_traceback(tmp_path, base, write_toml):
    base["agents"][1]["speed"] = -1.0
    path = write_toml(base)
    out = tmp_path / "out"
    res = invoke("sim", path, "--out", out, "--no-plots")
    assert res.exit_code == 2
    assert "Traceback" not in res.output
    assert "agents[1].speed" in res.stderr and str(path) in res.stderr
    assert len(res.stderr.strip().splitlines()) <= 3
    assert not out.exists()


def test_sim_on_missing_file(tmp_path):
    res = invoke("sim", tmp_path / "nope.toml", "--out", tmp_path / "o", "--no-plots")
    assert res.exit_code == 2 and "no such file" in res.stderr and "Traceback" not in res.output


def test_check_prints_summary_with_each_agent():
    for path in SCENARIOS:
        res = invoke("check", path)
        assert res.exit_code == 0, res.output
        s = load_scenario(path)
        assert res.stdout.startswith(f"{path}: ok")
        lines = res.stdout.splitlines()
        for a in s.agents:
            assert any(line.split()[:3] == ["agent", str(a.id), a.role] for line in lines), a.id
        assert f"{s.run.ticks} ticks" in res.stdout


def test_schema_is_valid_json_with_agents():
    res = invoke("schema")
    assert res.exit_code == 0
    schema = json.loads(res.stdout)
    assert "agents" in schema["properties"]
    assert "gains" in schema["required"] and "agents" in schema["required"]
    assert {"run", "target", "gains", "sensing"} <= set(schema["properties"])


@pytest.mark.parametrize("command", COMMANDS)
def test_help_for_every_command_has_an_example(command):
    res = invoke(command, "--help")
    assert res.exit_code == 0
    assert "Example: swarm " + command in res.stdout


def test_top_level_help_lists_commands():
    res = invoke("--help")
    assert res.exit_code == 0
    for c in COMMANDS:
        assert c in res.stdout


def test_plot_on_missing_dir(tmp_path):
    res = invoke("plot", tmp_path / "nope")
    assert res.exit_code == 2 and "not a directory" in res.stderr and "Traceback" not in res.output


# -- a follower law name that does not resolve --------------------------------------------


@pytest.fixture
def bad_law_file(base, write_toml):
    base["gains"]["law"] = "no_such_law"
    return write_toml(base)


def test_sim_with_unknown_law_exits_2_naming_the_field(bad_law_file, tmp_path):
    res = invoke("sim", bad_law_file, "--out", tmp_path / "o", "--no-plots", "--duration", "0.1")
    assert res.exit_code == 2
    assert isinstance(res.exception, SystemExit)
    assert "gains.law" in res.stderr and "no_such_law" in res.stderr


def test_check_with_unknown_law_exits_2_naming_the_field(bad_law_file):
    res = invoke("check", bad_law_file)
    assert res.exit_code == 2
    assert "gains.law" in res.stderr


# -- scenario values that cannot run: `swarm check` exits 2 with one line naming file and field --


def _check_fails(path, *fragments):
    res = invoke("check", path)
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit)
    assert "Traceback" not in res.output and "ok" not in res.stdout
    assert str(path) in res.stderr
    for frag in fragments:
        assert frag in res.stderr, f"{frag!r} not in {res.stderr!r}"
    return res.stderr.strip().splitlines()


def test_check_rejects_inf_duration(base, write_toml):
    path = write_toml(base)
    path.write_text(path.read_text().replace("duration = 10.0", "duration = inf"))
    lines = _check_fails(path, "run.duration", "finite")
    assert lines == [f"{path}: invalid scenario", "  run.duration: Input should be a finite number"]


def test_check_rejects_a_recording_too_large_for_memory(base, write_toml):
    base["run"].update(dt=0.001, duration=1e5)  # 1e8 ticks x (3 + 12) agents
    lines = _check_fails(write_toml(base), "run.duration", "1.5e+09 agent-ticks", "2e8", "larger run.dt")
    assert len(lines) == 2


def test_check_rejects_more_agents_than_the_wire_carries(base, write_toml):
    base["run"]["max_added_agents"] = 9998
    _check_fails(write_toml(base), "run.max_added_agents", "10001 agents", "(10000)")


def test_check_rejects_added_ids_past_the_wire(base, write_toml):
    base["agents"][2]["id"] = 2**31 - 2
    base["run"]["max_added_agents"] = 5
    _check_fails(write_toml(base), "agents[2].id", "2147483647", "run.max_added_agents = 1 or fewer")


def test_check_rejects_deep_nesting_in_one_line(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000)
    assert _check_fails(path, "nested too deeply") == [
        f"{path}: nested too deeply (arrays or tables inside one another)"
    ]


def test_check_rejects_a_binary_file(tmp_path):
    path = tmp_path / "binary.toml"
    path.write_bytes(bytes(range(256)))
    assert len(_check_fails(path, "cannot read: not UTF-8 text")) == 1


def test_check_shows_the_added_agents(base, write_toml):
    res = invoke("check", write_toml(base))
    assert res.exit_code == 0, res.output
    assert "  added agents: up to 12 (ids 4..15)\n" in res.stdout
    base["run"]["max_added_agents"] = 0
    res = invoke("check", write_toml(base))
    assert "  added agents: up to 0 (run.max_added_agents = 0)\n" in res.stdout


def test_progress_line_sums_up_a_large_swarm():
    from swarm.runtime.progress import progress_errors

    small = {"errors": {1: 0.0, 2: None, 3: 0.25}, "dropped": [4]}
    assert progress_errors(small) == "radial error 1:0.0% 2:- 3:25%  dropped 4"
    big = {"errors": {i: (None if i % 4 == 0 else i / 1000) for i in range(1, 201)}, "dropped": [201, 202]}
    line = progress_errors(big)
    # settled: within the 2% band (errors 0.1% .. 2.0%: agents 1..20 less the 5 without a leader)
    assert line == (
        "200 live: 15 settled, 135 not (worst 199:20% 198:20% 197:20%), 50 without a leader; dropped 201, 202"
    ), line
    many_dropped = progress_errors({**big, "dropped": list(range(201, 231))})
    assert many_dropped.endswith("; 30 dropped") and len(many_dropped) < 110, many_dropped
    assert (
        progress_errors({"errors": {i: None for i in range(20)}, "dropped": []})
        == "20 live: 0 settled, 20 without a leader"
    )
    assert progress_errors({"errors": {i: 0.001 for i in range(30)}, "dropped": []}) == "30 live: 30 settled"


def _command_paths(command, path=()):
    """Every command and group under `command` (a click command of typer's), as argv prefixes."""
    yield path
    for name, sub in sorted(getattr(command, "commands", {}).items()):
        yield from _command_paths(sub, (*path, name))


@pytest.mark.slow
def test_no_help_page_shows_a_flag_as_taking_a_value():
    # issue 33: typer's rich help printed every flag (--force, --plots/--no-plots, --help) with `<bool>`

    from swarm.cli.main import LAZY, build

    paths = list(_command_paths(command(app)))
    assert {("export",), ("study",), ("study", "scenario"), ("robots",), ("up",), ("kill",)} <= set(paths)
    pages = {}
    for path in paths:
        res = invoke(*path, "--help", env={"COLUMNS": "200"})
        assert res.exit_code == 0, (path, res.output)
        pages[path] = res.output
    # a live command's process builds its group alone (swarm/cli/main.py LAZY): its pages too
    for name, groups in LAZY.items():
        res = CliRunner().invoke(build(groups, study=False), [name, "--help"], env={"COLUMNS": "200"})
        assert res.exit_code == 0, (name, res.output)
        pages[("lazy", name)] = res.output
    shown = {path: page for path, page in pages.items() if "<bool>" in page}
    assert not shown, f"<bool> in the help of: {', '.join(' '.join(p) or 'swarm' for p in shown)}"
    # flags show no value; options that take one still say what
    lines = {line.split()[1]: line for line in pages[("export",)].splitlines() if line.startswith("│ --")}
    assert lines["--csv"].split()[2] == "also" and lines["--help"].split()[2] == "Show"
    assert lines["--plots"].split()[2:4] == ["--no-plots", "render"]
    assert "<float>" in pages[("sim",)]


def test_check_warns_of_an_arena_the_scenario_does_not_fit(tmp_path):
    """lab6 with its arena shrunk to 2.8 x 3.2 m: leader 4's orbit (R = 1.5 m + lookahead) no
    longer fits, and an agent starting within the lookahead of a wall is named; exit 0 (a warning)."""
    text = Path("scenarios/lab6.toml").read_text()
    assert "arena = [-2.0, -2.0, 2.0, 2.0]" in text
    path = tmp_path / "small.toml"
    path.write_text(text.replace("arena = [-2.0, -2.0, 2.0, 2.0]", "arena = [-1.2, -1.6, 1.6, 1.6]"))
    res = invoke("check", path)
    assert res.exit_code == 0, res.output
    warnings = [ln.strip() for ln in res.output.splitlines() if "warning:" in ln]
    assert any("leader 4's orbit" in w and "does not fit" in w for w in warnings), warnings
    assert not any("leader 1's orbit" in w for w in warnings), warnings  # R = 0.7 m fits
    assert any(w.startswith("warning: agent 2 starts") for w in warnings), warnings  # x = -1.15, the wall at -1.2
    path.write_text(text.replace("arena = [-2.0, -2.0, 2.0, 2.0]", "arena = [-1.0, -2.0, 2.0, 2.0]"))
    res = invoke("check", path)  # outside: an error, not a warning
    assert res.exit_code == 2 and "agent 2 starts at (-1.15, 0.05), outside safety.arena" in res.output
    assert "warning: agent" not in invoke("check", "scenarios/lab6.toml").output
