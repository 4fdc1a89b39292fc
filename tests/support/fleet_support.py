"""What the robot tests share: a robots file for the turtlebot scenario, a free TCP port, a
zenoh client of a fleet's router."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import zenoh


def robots_file(endpoint: str = "tcp/127.0.0.1:7447", **robot) -> dict:
    """The turtlebot scenario's two robots; `robot` overrides fields of agent 2's."""
    return {
        "ros2": {"connect": endpoint},
        "robots": [{"agent": 1, "namespace": "/tb3_0"}, {"agent": 2, "namespace": "/tb3_1", **robot}],
    }


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def client(endpoint: str) -> zenoh.Session:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("client"))
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


def write_robots(path: Path, data: dict) -> Path:
    lines = ["[ros2]"] + [f"{k} = {json.dumps(v)}" for k, v in data["ros2"].items()]
    for r in data["robots"]:
        lines += ["[[robots]]"] + [f"{k} = {json.dumps(v)}" for k, v in r.items()]
    path.write_text("\n".join(lines) + "\n")
    return path
