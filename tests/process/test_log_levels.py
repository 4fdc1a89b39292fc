"""`swarm -v` / `swarm -q` and $SWARM_LOG_LEVEL reach the processes `swarm up` starts
(swarm/contracts/log.py, docs/reference/cli.md#log-levels): the world's and the agents' logs carry
their debug lines with -v, and no info line with -q (tier process). Each run is a leader and a
follower for 0.1 s (lockstep): the logs are the point, not the swarm."""

from __future__ import annotations

import pytest
from runtime_helpers import ring_scenario, swarm_cmd

from swarm.contracts.log import ENV_LEVEL
from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow


def up(rt, out, *flags, env=None):
    scenario = ring_scenario(rt.tracker.log_dir / f"{out.name}.toml", 2, leaders=1, clock="lockstep", duration=0.1)
    args = swarm_cmd(*flags, "up", scenario, "--out", out, "--no-plots")
    p = rt.tracker.spawn(args, f"up-{out.name}", env={**rt.env, **(env or {})})
    assert p.wait(120) == ExitCode.OK, p.text()[-3000:]
    return (out / "logs" / "world.log").read_text(), (out / "logs" / "agent-1.log").read_text()


@pytest.mark.parametrize("how", ["flag", "environment"])
def test_verbose_reaches_the_world_and_the_agents(rt, tmp_path, how):
    flags, env = (("-v",), None) if how == "flag" else ((), {ENV_LEVEL: "debug"})
    world, agent = up(rt, tmp_path / how, *flags, env=env)
    assert "[world] run " in world and " agents, lockstep clock, endpoint " in world, world  # its debug line
    assert "[agent 1] joined run " in agent, agent
    assert "listening on" in world, world  # and its info lines


def test_quiet_keeps_only_warnings_and_errors(rt, tmp_path):
    world, agent = up(rt, tmp_path / "q", "-q", env={ENV_LEVEL: ""})
    assert "listening on" not in world and "waiting for agents" not in world, world
    assert "joined run" not in agent and "[agent 1]" not in agent, agent


def test_by_default_info_but_no_debug(rt, tmp_path):
    world, agent = up(rt, tmp_path / "d", env={ENV_LEVEL: ""})
    assert "listening on" in world and " agents, lockstep clock, endpoint " not in world, world
    assert "joined run" not in agent, agent
