"""Every process's diagnostics (swarm/contracts/log.py): the prefix ("[world] ..." notes,
"swarm world: ..." errors), the level from setup, from $SWARM_LOG_LEVEL and from `swarm -v/-q`,
and the command's name found after those flags (swarm/cli/main.py)."""

from __future__ import annotations

import logging
import os

import pytest
from typer.testing import CliRunner

from swarm.cli.main import build, command_at, foxglove_argv
from swarm.contracts import log as logs

log = logging.getLogger("swarm.world.test_probe")  # a module's logger, as every module has


@pytest.fixture(autouse=True)
def no_level(monkeypatch):
    monkeypatch.delenv(logs.ENV_LEVEL, raising=False)
    yield
    logs.setup("pytest", logging.INFO)


def test_notes_and_errors_look_as_they_always_did(capsys):
    logs.setup("world")
    log.info("run %s listening on %s", "r", "tcp/127.0.0.1:7447")
    log.error("cannot listen on %s: %s", "tcp/127.0.0.1:7", "Address in use")
    log.warning("SWARM_OPEN_HUB is set")
    log.error("swarm agent: agent 3 refused: no", extra=logs.VERBATIM)
    assert capsys.readouterr().err.splitlines() == [
        "[world] run r listening on tcp/127.0.0.1:7447",
        "swarm world: cannot listen on tcp/127.0.0.1:7: Address in use",
        "swarm world: SWARM_OPEN_HUB is set",
        "swarm agent: agent 3 refused: no",
    ]
    assert logs.prefix() == "world"


def test_an_agents_prefix_and_a_traceback_after_its_line(capsys):
    logs.setup("agent 3")
    try:
        raise ValueError("bad")
    except ValueError:
        log.exception("the law failed")
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "swarm agent 3: the law failed" and err[1] == "Traceback (most recent call last):", err
    assert err[-1] == "ValueError: bad", err


def test_the_level_from_setup_and_from_the_environment(capsys, monkeypatch):
    logs.setup("world", "WARNING")
    log.info("not shown")
    log.warning("shown")
    assert capsys.readouterr().err == "swarm world: shown\n"
    monkeypatch.setenv(logs.ENV_LEVEL, "debug")
    logs.setup("world")
    log.debug("a debug line")
    assert capsys.readouterr().err == "[world] a debug line\n"
    monkeypatch.setenv(logs.ENV_LEVEL, "40")
    logs.setup("world")
    log.warning("not shown")
    assert capsys.readouterr().err == ""
    monkeypatch.delenv(logs.ENV_LEVEL)
    logs.setup("world")
    log.debug("no debug by default")
    log.info("but info")
    assert capsys.readouterr().err == "[world] but info\n"


def test_a_bad_level_in_the_environment_is_said_and_info_is_used(capsys, monkeypatch):
    monkeypatch.setenv(logs.ENV_LEVEL, "LOUD")
    logs.setup("agent 2")
    log.info("still here")
    assert capsys.readouterr().err.splitlines() == [
        "swarm agent 2: SWARM_LOG_LEVEL='LOUD' is not a log level (one of DEBUG, INFO, WARNING, ERROR, or a number): "
        "INFO used",
        "[agent 2] still here",
    ]
    with pytest.raises(logs.LevelError, match="SWARM_LOG_LEVEL='LOUD'"):
        logs.parse_level("LOUD")


def test_one_handler_however_often_it_is_set_up(capsys):
    for name in ("swarm", "world", "world"):
        logs.setup(name)
    log.info("once")
    assert capsys.readouterr().err == "[world] once\n"


@pytest.mark.parametrize(
    ("flags", "level"), [(["-v"], "DEBUG"), (["--verbose"], "DEBUG"), (["-q"], "WARNING"), (["--quiet"], "WARNING")]
)
def test_swarm_v_and_q_set_the_level_for_this_process_and_its_children(monkeypatch, flags, level):
    monkeypatch.setenv(logs.ENV_LEVEL, "")  # (restored after the test: the command sets it)
    r = CliRunner().invoke(build(("offline",), study=False), [*flags, "check", "scenarios/case2.toml"])
    assert r.exit_code == 0, r.output
    assert os.environ[logs.ENV_LEVEL] == level  # what the world and agents it starts inherit
    assert logging.getLogger(logs.ROOT).level == getattr(logging, level)
    assert logs.prefix() == "check"


def test_v_and_q_together_are_refused(monkeypatch):
    monkeypatch.setenv(logs.ENV_LEVEL, "")
    r = CliRunner().invoke(build(("offline",), study=False), ["-v", "-q", "check", "scenarios/case2.toml"])
    assert r.exit_code == 2 and "-v and -q together" in r.output, r.output


def test_the_command_is_found_after_swarms_own_flags():
    assert command_at(["swarm", "-v", "up", "x"]) == 2 and command_at(["swarm", "up"]) == 1
    assert command_at(["swarm", "-q"]) == 2
    assert foxglove_argv(["swarm", "-v", "up", "s.toml", "--foxglove", "9000"]) == [
        "swarm",
        "-v",
        "up",
        "s.toml",
        "--foxglove",
        "--foxglove-port",
        "9000",
    ]
