"""A Foxglove layout made for one run: a 3D panel of `/swarm/scene` and `/swarm/trails`,
plots of each of the run's own agents' radial error and turn rate (paths into
`/swarm/agents`, one per agent id: `/swarm/agents.agents[:]{id==N}.radial_error`), and
`/swarm/events` as raw messages. The topics are those world/scene.py writes into the
recording and world/live_view.py serves (docs/reference/outputs.md#foxglove).

`foxglove_layout(agents)` builds it (a dict, Foxglove's layout JSON), `write_layout(out,
agents)` writes it as `<out>/foxglove-layout.json`: `swarm up --foxglove` into the run's
output directory as the run starts (the scenario's agents), `swarm plot` next to the
figures (the run's agents, with any added during the run). Agents are `(id, role)` pairs;
leaders are labelled "L<id>" as in the figures. docs/foxglove-layout.json is case 2's."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.scenario import Scenario

LAYOUT_FILE = "foxglove-layout.json"
SCENE_TOPICS = ("/swarm/scene", "/swarm/trails")
AGENTS_TOPIC = "/swarm/agents"
EVENTS_TOPIC = "/swarm/events"
#: The plots of the layout: panel id -> (title, field of an agent in /swarm/agents).
PLOTS = {
    "Plot!radial": ("radial error |r - R| (m)", "radial_error"),
    "Plot!turn": ("turn rate u (rad/s)", "u"),
}
LEADER = "leader"  # trajectory.npz's and the scenario's role of a leader
DEFAULT_EXTENT = 100.0  # m: the view's half-width when the run's extent is not known


def agent_path(agent_id: int, field: str) -> str:
    """The message path of one agent's `field` in /swarm/agents (Foxglove's filter syntax)."""
    return f"{AGENTS_TOPIC}.agents[:]{{id=={int(agent_id)}}}.{field}"


def agent_label(agent_id: int, role: str) -> str:
    """'L1' for leader 1, 'agent 4' for follower 4."""
    return f"L{int(agent_id)}" if role == LEADER else f"agent {int(agent_id)}"


def _plot(title: str, field: str, agents: list[tuple[int, str]]) -> dict[str, Any]:
    return {
        "title": title,
        "paths": [
            {
                "value": agent_path(i, field),
                "enabled": True,
                "timestampMethod": "receiveTime",
                "label": agent_label(i, role),
            }
            for i, role in agents
        ],
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "floating",
        "isSynced": True,
        "xAxisVal": "timestamp",
        "sidebarDimension": 240,
    }


def _scene(extent: float, centre: tuple[float, float]) -> dict[str, Any]:
    """The 3D panel, seen from above, on `centre` (the target), the grid and the camera sized
    to `extent` (m)."""
    at = [round(float(centre[0]), 3), round(float(centre[1]), 3), 0]
    cells = 10.0 ** math.floor(math.log10(max(extent, 1.0) / 2.0))  # a round cell size, 5-50 cells a side
    size = cells * math.ceil(4.0 * extent / cells)
    return {
        "layers": {
            "grid": {
                "layerId": "foxglove.Grid",
                "visible": True,
                "frameId": "world",
                "size": size,
                "divisions": int(round(size / cells)),
                "position": at,
                "rotation": [0, 0, 0],
            }
        },
        "followMode": "follow-none",
        "followTf": "world",
        "scene": {"enableStats": False, "transforms": {"showLabel": False}},
        "cameraState": {
            "perspective": False,
            "distance": round(2.5 * extent, 1),
            "phi": 0,
            "thetaOffset": 90,
            "targetOffset": [0, 0, 0],
            "target": at,
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.5,
            "far": max(5000, round(50.0 * extent)),
        },
        "topics": {topic: {"visible": True} for topic in SCENE_TOPICS},
    }


def foxglove_layout(
    agents: Iterable[tuple[int, str]], extent: float = DEFAULT_EXTENT, centre: tuple[float, float] = (0.0, 0.0)
) -> dict[str, Any]:
    """The layout (Foxglove's layout JSON, as a dict) for agents `(id, role)`, in the order
    given, once each; `extent` (m): about the largest distance of an agent from `centre`,
    the target, which the view is centred on."""
    seen: dict[int, str] = {}
    for i, role in agents:
        seen.setdefault(int(i), str(role))
    own = list(seen.items())
    if not math.isfinite(extent) or extent <= 0:
        extent = DEFAULT_EXTENT
    config: dict[str, Any] = {"3D!swarm": _scene(extent, centre)}
    for panel, (title, field) in PLOTS.items():
        config[panel] = _plot(title, field, own)
    config["RawMessages!events"] = {
        "topicPath": EVENTS_TOPIC,
        "diffEnabled": False,
        "diffMethod": "custom",
        "diffTopicPath": "",
        "showFullMessageForDiff": False,
        "expansion": "all",
    }
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {
            "direction": "row",
            "splitPercentage": 55,
            "first": "3D!swarm",
            "second": {
                "direction": "column",
                "first": "Plot!radial",
                "second": {
                    "direction": "column",
                    "first": "Plot!turn",
                    "second": "RawMessages!events",
                    "splitPercentage": 55,
                },
                "splitPercentage": 40,
            },
        },
    }


def layout_text(
    agents: Iterable[tuple[int, str]], extent: float = DEFAULT_EXTENT, centre: tuple[float, float] = (0.0, 0.0)
) -> str:
    """The layout as the file holds it (indented JSON, a final newline)."""
    return json.dumps(foxglove_layout(agents, extent, centre), indent=2) + "\n"


def write_layout(
    out: Path,
    agents: Iterable[tuple[int, str]],
    extent: float = DEFAULT_EXTENT,
    centre: tuple[float, float] = (0.0, 0.0),
) -> Path:
    """Write `<out>/foxglove-layout.json` (whole or not at all: a temporary name, then
    renamed) and return its path."""
    path = Path(out) / LAYOUT_FILE
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(layout_text(agents, extent, centre))
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def scenario_agents(scenario: Scenario) -> tuple[list[tuple[int, str]], float, tuple[float, float]]:
    """A scenario's `(id, role)` pairs, its extent (twice the farthest start or orbit from the
    target, m, so that the view holds the whole swarm) and its target."""
    tx, ty = float(scenario.target.x), float(scenario.target.y)
    agents: list[tuple[int, str]] = []
    far = 0.0
    for a in scenario.agents:
        agents.append((int(a.id), str(a.role)))
        far = max(far, math.hypot(float(a.x) - tx, float(a.y) - ty), float(a.orbit_radius or 0.0))
    return agents, (far * 2.0 if far > 0 else DEFAULT_EXTENT), (tx, ty)  # room for the followers' wider orbits


def run_agents(
    ids: Iterable[Any], roles: Iterable[Any], x: Any = None, y: Any = None, target: Any = None
) -> tuple[list[tuple[int, str]], float, tuple[float, float]]:
    """A finished run's `(id, role)` pairs (trajectory.npz's `ids` and `role`), its extent
    (the farthest any agent got from the target, m; DEFAULT_EXTENT without positions) and
    its target ((0, 0) without one)."""
    agents = [(int(i), str(r)) for i, r in zip(ids, roles)]
    extent = DEFAULT_EXTENT
    centre = (0.0, 0.0) if target is None else (float(target[0]), float(target[1]))
    if x is not None and y is not None:
        d = np.hypot(np.asarray(x, dtype=float) - centre[0], np.asarray(y, dtype=float) - centre[1])
        d = d[np.isfinite(d)]
        if d.size:
            extent = max(1.0, float(d.max()) * 1.1)
    return agents, extent, centre
