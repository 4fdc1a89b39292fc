"""Live inspection and control commands (`swarm runs/agents/graph/kill/spawn/pause/resume/watch`)."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    """Add the live commands to the main app."""
