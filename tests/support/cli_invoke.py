"""`swarm ARGS` in the test process (typer's CliRunner) on the click command built once:
typer's `CliRunner.invoke(app, ...)` builds the command from the app at every call, about
0.1 s of CPU, which was most of the time of a test of a quick command. The built command is
handed to typer's runner in place of its own builder (a private name of typer.testing: if
typer renames it, these tests error, they do not pass)."""

from __future__ import annotations

from functools import cache
from typing import Any
from unittest import mock

from typer.main import get_command
from typer.testing import CliRunner

from swarm.cli.main import app

command = cache(get_command)


def invoke(*args: Any, **kwargs: Any):
    """`swarm ARGS` in this process: typer's Result (exit_code, stdout, stderr, output)."""
    with mock.patch("typer.testing._get_command", command):
        return CliRunner().invoke(app, [str(a) for a in args], **kwargs)
