"""The messages users read (issue 22, items 7 and 9): each says in one line what happened,
naming the option, field or file, and no command answers bad input with a traceback or
typer's usage box. Commands run in this process (click's CliRunner on the command typer builds
from `app`, built once for the module: typer's CliRunner builds it again on every call, about 0.1 s
of CPU each), and one command of each kind of message as a process of its own (the command the
issue quotes, and a bad option value: typer's usage errors in a real `swarm` process).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from deadlines import DEADLINE
from typer.main import get_command

from swarm.cli.main import app

ROOT = Path(__file__).resolve().parents[2]
CASE2 = ROOT / "scenarios" / "case2.toml"


@pytest.fixture(autouse=True)
def _private_runtime_dir(tmp_path, monkeypatch):
    """No command here may find (or touch) the runs of the machine."""
    d = tmp_path / "rt"
    d.mkdir(mode=0o700)
    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(d))
    for var in ("SWARM_RUN", "SWARM_CONNECT", "SWARM_CREDENTIALS"):
        monkeypatch.delenv(var, raising=False)


_COMMAND = get_command(app)  # what typer.testing.CliRunner.invoke(app, ...) builds on every call


def invoke(*args):
    return CliRunner().invoke(_COMMAND, [str(a) for a in args])


def one_line(res, code: int = 2) -> str:
    """The one line a failed command printed (all its output), checked for the exit code and
    the absence of a traceback and of typer's box."""
    assert res.exit_code == code, (res.exit_code, res.output)
    assert "Traceback" not in res.output and "╭" not in res.output and "Usage:" not in res.output, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1, res.output
    return lines[0]


# -- item 7: a law must be a Python function ----------------------------------------------------------


class _Callable:
    def __call__(self, obs):
        return 0.0


law_object = _Callable()  # helpers for the table below: this module is importable as `test_messages`


@pytest.mark.parametrize(
    "table, key, name, field, what",
    [
        ("law", "follower", "os:system", "law.follower", "is a builtin"),
        ("law", "leader", "collections:OrderedDict", "law.leader", "is a class"),
        ("gains", "law", "math:hypot", "gains.law", "is a builtin"),
        ("law", "follower", "test_messages:law_object", "law.follower", "is a _Callable object"),
    ],
)
def test_a_law_that_is_not_a_python_function_is_refused(base, write_toml, table, key, name, field, what):
    base.setdefault(table, {})[key] = name
    path = write_toml(base)
    res = invoke("check", path)
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    lines = res.stderr.strip().splitlines()
    assert lines[0] == f"{path}: invalid scenario"
    assert len(lines) == 2 and lines[1].startswith(f"  {field}: "), lines
    assert what in lines[1] and "not a Python function" in lines[1] and name in lines[1], lines[1]


# -- item 7 and 9: endpoints ------------------------------------------------------------------------

BAD_ENDPOINTS = {
    "tcp/127.0.0.1:99999": "port 99999 is not in ",  # 1..65535; 0..65535 for --listen
    "foo/bar": "use tcp/HOST:PORT, tls/HOST:PORT or unixsock-stream/PATH",
    "tcp/127.0.0.1": "no port",
    "tcp/:7447": "no host",
    "tcp/127.0.0.1:x": "port 'x' is not a number",
    "unixsock-stream/": "no socket path",
}


@pytest.mark.parametrize("endpoint", sorted(BAD_ENDPOINTS))
@pytest.mark.parametrize(
    "command, option",
    [
        (("agent", "--id", "1", "--connect"), "--connect"),
        (("agents", "--connect"), "--connect"),
        (("runs", "--json", "--connect"), "--connect"),
        (("pause", "--connect"), "--connect"),
        (("host", "--connect"), "--connect"),
        (("up", CASE2, "--listen"), "--listen"),
        (("world", CASE2, "--listen"), "--listen"),
        (("credentials", "--operator", "--endpoint"), "--endpoint"),
    ],
)
def test_an_endpoint_that_is_not_one_is_one_line(command, option, endpoint):
    line = one_line(invoke(*command, endpoint))
    assert line.startswith(f"{option}: not an endpoint: {endpoint!r} (") and BAD_ENDPOINTS[endpoint] in line, line


@pytest.mark.slow  # a process start each (about 0.5 s): the fast tier has the same messages in-process above
@pytest.mark.parametrize(
    "args, said",
    [
        # `swarm agent --id 1 --connect tcp/127.0.0.1:99999` was a 30-line OverflowError (the command)
        (
            ("agent", "--id", "1", "--connect", "tcp/127.0.0.1:99999"),
            "--connect: not an endpoint: 'tcp/127.0.0.1:99999' (port 99999 is not in 1..65535)",
        ),
        # a bad option value: typer's usage error, one line in a real process too (not typer's box)
        (("sim", CASE2, "--duration", "-5"), f"--duration -5: should be greater than 0 ({CASE2})"),
    ],
    ids=["endpoint", "option-value"],
)
def test_a_message_is_one_line_from_a_swarm_process(args, said):
    env = {**os.environ, "SWARM_RUNTIME_DIR": os.environ["SWARM_RUNTIME_DIR"]}
    p = subprocess.run(
        [sys.executable, "-m", "swarm", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=DEADLINE,
        env=env,
        cwd=ROOT,
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr and "╭" not in p.stderr, p.stderr
    assert p.stderr.strip() == said and p.stdout == "", (p.stdout, p.stderr)


def test_endpoints_that_are_endpoints_pass():
    from swarm.contracts.endpoints import EndpointError, check_endpoint

    for ep in (
        "tcp/127.0.0.1:7447",
        "tls/hub.lan:7447",
        "tcp/[::1]:7447",
        "unixsock-stream//tmp/x.sock",
        "tcp/10.0.0.5:7447#iface=lo",
        "tcp/h:65535",
        "tcp/h:1",
    ):
        assert check_endpoint(ep) == ep
    assert check_endpoint("tcp/0.0.0.0:0", listen=True) == "tcp/0.0.0.0:0"  # any free port
    for ep in ("tcp/0.0.0.0:0", "tcp/h:65536", "tcp/::1:7447", "hub.lan:7447", "", "udp/h:1"):
        with pytest.raises(EndpointError, match="not an endpoint"):
            check_endpoint(ep)


# -- item 9: the cause of an exit -------------------------------------------------------------------


def test_a_killed_world_is_not_given_its_last_progress_line_as_cause(tmp_path):
    from swarm.runtime.supervision import world_failure

    log = tmp_path / "world.log"
    log.write_text(
        "[world] run r listening on unixsock-stream//tmp/x.sock\n[world] tick 1200/15000 t=12.00s 95 ticks/s\n"
    )
    assert world_failure(-signal.SIGKILL, True, log) == "the world failed (killed by SIGKILL)"
    log.write_text(
        "[world] run r listening\nswarm world: cannot listen on tcp/127.0.0.1:7: Address in use at "
        "/root/.cargo/zenoh/src/lib.rs:62.\n"
    )
    assert (
        world_failure(2, False, log)
        == "the world could not start (exit code 2): swarm world: cannot listen on tcp/127.0.0.1:7: Address in use"
    )
    log.write_text('[world] tick 3\nTraceback (most recent call last):\n  File "x.py", line 1, in f\nValueError: bad\n')
    assert world_failure(1, True, log) == "the world failed (exit code 1): ValueError: bad"


def test_a_crash_line_quotes_no_unrelated_log_line(tmp_path):
    from swarm.runtime.supervision import agent_exit

    log = tmp_path / "agent-2.log"
    log.write_text("[agent 2] tick 1: out-neighbour 1 -> 3 (nearest)\n")
    r = agent_exit(2, 42, -signal.SIGSEGV, log, before_start=False)
    assert r.crash and r.line() == "agent 2 (pid 42) crashed (killed by SIGSEGV)"
    log.write_text(
        '[agent 2] tick 1: x\nTraceback (most recent call last):\n  File "law.py", line 3\n'
        "RuntimeError: the law gave up\n"
    )
    assert (
        agent_exit(2, 42, 1, log, False).line()
        == "agent 2 (pid 42) crashed (exit code 1): RuntimeError: the law gave up"
    )
    deep = "".join(f'  File "m.py", line {k}, in f\n    f()\n' for k in range(30))  # its header out of the tail
    log.write_text(f"Traceback (most recent call last):\n{deep}RecursionError: too deep\n")
    assert agent_exit(2, 42, 1, log, False).cause == "RecursionError: too deep"
    log.write_text("[agent 2] tick 9: x\nswarm agent: the world of run r vanished; exiting\n")
    assert (
        agent_exit(2, 42, 4, log, False).line()
        == "agent 2 (pid 42) exited (exit code 4): swarm agent: the world of run r vanished; exiting"
    )
    log.write_text("[agent 2] tick 9: x\n")
    assert agent_exit(2, 42, 4, log, False).line() == "agent 2 (pid 42) exited (exit code 4): the world vanished"


def test_killed_by_sigkill_is_said_once(tmp_path):
    from swarm.runtime.supervision import agent_exit

    r = agent_exit(3, 43, -signal.SIGKILL, tmp_path / "none.log", before_start=False)
    assert r.line() == "agent 3 (pid 43) exited (killed by SIGKILL)"
    assert r.said() == ""  # what the world is told: it says the status itself


# -- item 9: credentials ------------------------------------------------------------------------------


def test_a_file_that_is_not_credentials_gets_no_chmod_advice(tmp_path):
    f = tmp_path / "passwd"
    f.write_text("root:x:0:0:root:/root:/bin/bash\n")
    f.chmod(0o644)
    for args, code in (
        (("agents", "--credentials", f), 1),
        (("runs", "--credentials", f), 1),
        (("agent", "--id", "1", "--connect", "tcp/127.0.0.1:7", "--credentials", f), 3),
        (("host", "--credentials", f), 2),
    ):
        line = one_line(invoke(*args), code)
        assert f"{f}: not a credentials file" in line and "chmod" not in line, (args, line)


def test_a_credentials_file_readable_by_others_still_gets_the_advice(tmp_path):
    from swarm.contracts import credentials as C
    from swarm.contracts.identities import CredentialsError

    f = C.write(C.new_credentials("r1", "tcp/127.0.0.1:7447"), tmp_path / "r1.cred")
    f.chmod(0o644)
    with pytest.raises(CredentialsError, match=r"readable by others .*chmod 600"):
        C.read(f)


# -- item 9: numbers out of range, and the rest of typer's usage errors: one line -------------------


@pytest.mark.parametrize(
    "args, lead",
    [
        (("sim", CASE2, "--duration", "-5"), "--duration -5: should be greater than 0"),
        (("sim", CASE2, "--duration", "0"), "--duration 0: should be greater than 0"),
        (("sim", CASE2, "--duration", "nan"), "--duration nan: should be a finite number"),
        (("sim", CASE2, "--duration", "abc"), "--duration abc: should be a valid number"),
        (("world", CASE2, "--duration", "-5"), "--duration -5: should be greater than 0"),
        (("up", CASE2, "--duration", "-5"), "--duration -5: should be greater than 0"),
        (("up", CASE2, "--time-scale", "0"), "--time-scale 0: should be greater than or equal to"),
        (("up", CASE2, "--world-grace", "-1"), "--world-grace -1: should be greater than or equal to 0"),
        (("up", CASE2, "--foxglove-port", "70000"), "--foxglove-port 70000: should be less than or equal to 65535"),
        (("agent", "--id", "-1", "--connect", "tcp/127.0.0.1:7"), "--id -1: should be greater than or equal to 0"),
        (
            ("agent", "--id", "2147483648", "--connect", "tcp/127.0.0.1:7"),
            "--id 2147483648: should be less than or equal to 2147483647",
        ),
        (("agent", "--id", "1", "--connect", "tcp/127.0.0.1:7", "--connect-timeout", "-1"), "--connect-timeout -1:"),
        (("spawn", "--id", "-1"), "--id -1: should be greater than or equal to 0"),
        (("kill", "2147483648"), "ID 2147483648: should be less than or equal to 2147483647"),
        (("credentials", "--agent", "-1"), "--agent -1: should be greater than or equal to 0"),
        (("host", "--wait", "-1"), "--wait -1: should be greater than or equal to 0"),
        (("watch", "--rate", "100"), "--rate 100: should be less than or equal to 30"),
        (("study", "swarms", "--seeds", "0"), "--seeds 0: should be greater than or equal to 1"),
        (("study", "gains", "--starts", "0"), "--starts 0: should be greater than or equal to 1"),
        (("sim", CASE2, "--nope"), "swarm sim: no such option: --nope"),
        (("agent", "--connect", "tcp/127.0.0.1:7"), "swarm agent: missing option '--id'"),
    ],
)
def test_bad_option_values_are_one_line(args, lead):
    line = one_line(invoke(*args))
    assert line.startswith(lead), line


# -- item 9: singular and plural; the added-id range; option names; the progress line ---------------


def test_one_switch_is_one_switch(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from synthetic_run import make_run

    from swarm.plots import load_run
    from swarm.plots.context import make_context
    from swarm.plots.graph import panel_graph, panel_neighbours

    run_dir = make_run(tmp_path / "run", drop=None)
    with np.load(run_dir / "trajectory.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["out"][100:, 2] = 1  # follower 3: 2 -> 1 at tick 100, and keeps it: one switch
    np.savez(run_dir / "trajectory.npz", **arrays)
    ctx = make_context(load_run(run_dir))
    fig, (a, b) = plt.subplots(1, 2)
    try:
        panel_graph(a, ctx)
        panel_neighbours(b, ctx)
        titles = a.get_title() + " | " + b.get_title()
    finally:
        plt.close(fig)
    assert "after 1 switch" in titles and "(1 switch)" in titles and "switches" not in titles, titles


@pytest.mark.slow
def test_no_id_left_to_add_is_said_so(base, write_toml):
    from swarm.cli.up import attach_hints

    base["agents"][-1]["id"] = 2**31 - 1
    path = write_toml(base)
    res = invoke("check", path)
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.stdout.splitlines() if "added agents" in ln)
    assert "2147483648" not in line and "run.max_added_agents = 0" not in line, line
    assert (
        line == "  added agents: up to 0 (agent 2147483647 has the largest id the wire carries, so no id is "
        "left after it)"
    ), line
    from swarm.contracts.scenario import load_scenario

    hints = " ".join(attach_hints("r-1", "unixsock-stream//tmp/x.sock", load_scenario(path)))
    assert "2147483648" not in hints and "no new id" in hints, hints
    base["run"]["max_added_agents"] = 5
    res = invoke("check", write_toml(base))
    assert res.exit_code == 2 and "or fewer" not in res.stderr and "run.max_added_agents = 0" in res.stderr, res.output


def test_agent_has_one_option_named_after_waiting_for_the_world():
    res = invoke("agent", "--help")
    assert res.exit_code == 0
    assert "--wait-world" in res.output and "--connect-timeout" in res.output
    assert "--world-wait" not in res.output  # the old name, kept hidden for old scripts


def test_progress_line_says_paused(monkeypatch, capsys):
    import time as time_module

    from swarm.runtime.progress import Paused, ProgressLine

    now = [100.0]
    monkeypatch.setattr(time_module, "monotonic", lambda: now[0])
    line = ProgressLine(tty=False)
    fig = {"time": 1.0, "ticks": 1000, "errors": {1: 0.0}, "dropped": []}
    line.show({**fig, "tick": 100, "wall": 1.0})
    now[0] += 1.5
    line.show({**fig, "tick": 102, "wall": 2.0})  # 2 ticks/s as the pause takes hold
    for k in range(3):
        now[0] += 1.5
        line.show({**fig, "tick": 102, "wall": 3.0 + k, "paused": True})
    out = capsys.readouterr().out.strip().splitlines()
    assert "2 ticks/s" in out[1] and "paused" in out[-1] and "ticks/s" not in out[-1], out
    assert len(out) == 3  # said once while it stays paused (not a tty: a log)
    now[0] += 1.5
    line.show({**fig, "tick": 202, "wall": 7.0})  # resumed: 100 ticks in the 2 s since the last paused figures
    assert "50 ticks/s" in capsys.readouterr().out
    paused = Paused()
    assert not paused([{"kind": "start"}])
    assert paused([{"kind": "start"}, {"kind": "pause"}])
    assert not paused([{"kind": "start"}, {"kind": "pause"}, {"kind": "switch"}, {"kind": "resume"}])


def test_the_python_api_says_not_an_endpoint():
    """swarm.connect / swarm.runs with connect="foo/bar": UsageError, one line (not "no run")."""
    import swarm
    from swarm.contracts.errors import UsageError

    for call in (swarm.connect, swarm.runs):
        with pytest.raises(UsageError) as e:
            call(connect="foo/bar")
        assert str(e.value).startswith("connect: not an endpoint: 'foo/bar'") and "\n" not in str(e.value)
