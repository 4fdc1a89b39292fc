"""ROBOTIS' zenoh-ros2-sdk (an independent rmw_zenoh client) for the tests, offline: its message
definitions written from rosbags' Jazzy store into its registry's directory (which it reads
before it would git-clone ros2/common_interfaces), its git cache in a tmp dir (asserted unused
by the tests), and its process-wide session pointed at a test's router as a client."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh_ros2_sdk
import zenoh_ros2_sdk.message_registry
from rosbags.typesys import Stores, get_typestore


def write_msgs(out: Path, roots: list[str]) -> Path:
    """.msg files (<pkg>/msg/<Name>.msg) of `roots` and of what they use, from rosbags' Jazzy store."""
    store = get_typestore(Stores.ROS2_JAZZY)
    sep = "=" * 80 + "\n"
    for root in roots:
        text, _ = store.generate_msgdef(root, ros_version=2)
        chunks = text.split(sep)
        names = [root] + [c.split("\n", 1)[0].removeprefix("MSG: ") for c in chunks[1:]]
        bodies = [chunks[0]] + [c.split("\n", 1)[1] for c in chunks[1:]]
        for name, body in zip(names, bodies, strict=True):
            pkg, _, base = name.partition("/")
            path = out / pkg / "msg" / f"{base.removeprefix('msg/')}.msg"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(body)
    return out


def sdk_offline(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, endpoint: str, roots: list[str]) -> Path:
    """Point the SDK at `endpoint` (client mode) with the messages `roots` written into
    tmp_path/msgs; returns its git cache directory (tmp_path/cache), which must stay absent."""
    msgs = write_msgs(tmp_path / "msgs", roots)
    cache = tmp_path / "cache"
    monkeypatch.setenv("ZENOH_ROS2_SDK_CACHE", str(cache))
    monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", f'mode="client";connect/endpoints=["{endpoint}"];listen/endpoints=[]')
    monkeypatch.setattr(zenoh_ros2_sdk.message_registry, "_registry", zenoh_ros2_sdk.MessageRegistry(str(msgs)))
    monkeypatch.setattr(zenoh_ros2_sdk.ZenohSession, "_instance", None)
    return cache
