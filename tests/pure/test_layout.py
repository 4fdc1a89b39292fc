"""Foxglove layouts made for a run (swarm/offline/layout.py): the scenario's own agents'
topics, nothing of another scenario's, paths that the recording's /swarm/agents messages
resolve, and docs/foxglove-layout.json as case 2's."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from synthetic_run import make_run
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.cli.up import run_layout
from swarm.contracts.scenario import load_scenario
from swarm.offline.layout import LAYOUT_FILE, layout_text, run_agents, scenario_agents, write_layout
from swarm.world.live_view import LIVE_TOPICS
from swarm.world.scene import SceneBuilder

ROOT = Path(__file__).resolve().parents[2]
CASE2 = ROOT / "scenarios" / "case2.toml"
PATH_ID = re.compile(r"^/swarm/agents\.agents\[:\]\{id==(\d+)\}\.(\w+)$")


def ten_agent_scenario(tmp_path: Path) -> Path:
    """Ids 21..30 (none of case 2's 1..6): leaders 21 and 26, the others follow."""
    lines = ['name = "ten"', "[run]", "dt = 0.01", "duration = 1.0", "[target]", "x = 5.0", "y = -3.0"]
    lines += ["[gains]", "c1 = 1.0", "c2 = 0.5"]
    for k, i in enumerate(range(21, 31)):
        lines += ["[[agents]]", f"id = {i}", f"x = {10.0 * k - 40.0}", f"y = {3.0 * k}", "heading = 0.5"]
        if i in (21, 26):
            lines += ['role = "leader"', "speed = 20.0", "orbit_radius = 20.0"]
        else:
            lines += ['role = "follower"', f"speed = {15.0 + k}"]
    path = tmp_path / "ten.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def ids_in(layout: dict) -> dict[str, list[int]]:
    """Per plot panel, the agent ids its paths name (in order); every path must parse."""
    out: dict[str, list[int]] = {}
    for panel, cfg in layout["configById"].items():
        if panel.startswith("Plot!"):
            found = [PATH_ID.match(p["value"]) for p in cfg["paths"]]
            assert all(found), [p["value"] for p in cfg["paths"]]
            out[panel] = [int(m.group(1)) for m in found if m]
    return out


def topics_in(layout: dict) -> set[str]:
    """Every topic the layout reads: the 3D panel's, the plots' and the raw messages'."""
    cfg = layout["configById"]
    topics = set(cfg["3D!swarm"]["topics"])
    for panel, c in cfg.items():
        if panel.startswith("Plot!"):
            topics |= {p["value"].split(".", 1)[0] for p in c["paths"]}
        if panel.startswith("RawMessages!"):
            topics.add(c["topicPath"])
    return topics


def test_a_ten_agent_layout_names_exactly_its_agents(tmp_path: Path) -> None:
    s = load_scenario(ten_agent_scenario(tmp_path))
    agents, extent, centre = scenario_agents(s)
    path = write_layout(tmp_path, agents, extent, centre)
    assert path == tmp_path / LAYOUT_FILE
    layout = json.loads(path.read_text())  # opened as JSON
    ids = ids_in(layout)
    assert set(ids) == {"Plot!radial", "Plot!turn"}
    for panel, got in ids.items():
        assert got == list(range(21, 31)), panel  # each agent once, in the scenario's order
    labels = [p["label"] for p in layout["configById"]["Plot!turn"]["paths"]]
    assert labels[0] == "L21" and labels[5] == "L26" and labels[1] == "agent 22"
    # none of another scenario's: case 2's layout names 1..6, this one none of them
    case2 = json.loads(layout_text(*scenario_agents(load_scenario(CASE2))))
    assert all(got == [1, 2, 3, 4, 5, 6] for got in ids_in(case2).values())
    assert not {i for got in ids.values() for i in got} & {i for got in ids_in(case2).values() for i in got}
    # centred on the scenario's target, the camera far enough for its starts
    scene = layout["configById"]["3D!swarm"]
    assert scene["cameraState"]["target"] == [5.0, -3.0, 0]
    assert scene["cameraState"]["distance"] >= 2.0 * 45.0


def test_the_layout_reads_only_topics_the_run_serves_and_records(tmp_path: Path) -> None:
    """Its topics are the live view's (the recording's but /swarm/ticks), and each plot path
    resolves in a /swarm/agents message built as the world builds it (world/scene.py)."""
    s = load_scenario(ten_agent_scenario(tmp_path))
    layout = json.loads(layout_text(*scenario_agents(s)))
    assert topics_in(layout) <= set(LIVE_TOPICS)
    assert {"/swarm/scene", "/swarm/agents", "/swarm/events"} <= topics_in(layout)
    n = len(s.agents)
    ids = np.array([a.id for a in s.agents])
    b = SceneBuilder((s.target.x, s.target.y), s.agents, scene_rate=10.0)
    out = np.array([-1 if a.role == "leader" else (21 if a.id < 26 else 26) for a in s.agents])
    msg = b.numbers(0, 0.0, ids, np.zeros(n), np.ones(n), np.zeros(n), np.full(n, 0.3), out, np.ones(n, bool))
    rows = {r["id"]: r for r in msg["agents"]}
    for panel, cfg in layout["configById"].items():
        for p in cfg.get("paths", []):
            m = PATH_ID.match(p["value"])
            assert m is not None
            row = rows[int(m.group(1))]
            assert m.group(2) in row, (panel, p["value"])
            assert row[m.group(2)] is not None  # alive and rooted: a number to plot


def test_a_runs_layout_has_its_agents_and_the_docs_layout_is_case2s(tmp_path: Path) -> None:
    agents, extent, centre = run_agents(
        np.array([4, 9, 2]), np.array(["leader", "follower", "follower"]), np.array([[0.0, 30.0, -10.0]]),
        np.array([[0.0, 0.0, 0.0]]), np.array([1.0, 0.0]),
    )  # fmt: skip
    assert agents == [(4, "leader"), (9, "follower"), (2, "follower")]
    assert centre == (1.0, 0.0) and abs(extent - 29.0 * 1.1) < 1e-9
    assert ids_in(json.loads(layout_text(agents, extent, centre)))["Plot!radial"] == [4, 9, 2]
    # the shipped file is the generator's output for case 2 (regenerate it when the layout changes)
    assert (ROOT / "docs" / "foxglove-layout.json").read_text() == layout_text(*scenario_agents(load_scenario(CASE2)))


@pytest.mark.slow
def test_swarm_plot_writes_the_runs_layout(tmp_path: Path) -> None:
    """`swarm plot` writes foxglove-layout.json next to the figures, for the run's agents."""
    run_dir = make_run(tmp_path / "run", ticks=60, n_leaders=2, n_followers=3)
    r = CliRunner().invoke(app, ["plot", str(run_dir)])
    assert r.exit_code == 0, r.output
    assert "foxglove layout: foxglove-layout.json (5 agents" in r.output
    layout = json.loads((run_dir / LAYOUT_FILE).read_text())
    assert all(got == [1, 2, 3, 4, 5] for got in ids_in(layout).values())


def test_swarm_up_foxglove_writes_the_scenarios_layout_and_says_where(tmp_path: Path) -> None:
    """What `swarm up --foxglove` does as the run starts (swarm/cli/up.py's run_layout): the
    layout for the scenario's agents in the run's output directory, one line naming it; a
    directory it cannot write to is said in that line, and the run goes on."""
    s = load_scenario(ten_agent_scenario(tmp_path))
    out = tmp_path / "run"
    out.mkdir()
    line = run_layout(s, out)
    assert line.startswith(f"layout for its 10 agents: {out / LAYOUT_FILE}")
    assert all(got == list(range(21, 31)) for got in ids_in(json.loads((out / LAYOUT_FILE).read_text())).values())
    missing = tmp_path / "gone"
    assert run_layout(s, missing).startswith(f"layout: not written ({missing}")
    assert not missing.exists()
