"""The everyday live commands `swarm logs`, `swarm stop` and `swarm echo` (swarm/cli/tools.py,
swarm/live/logs.py, stop.py, tap.py).

Offline: the keys `swarm echo` takes and refuses, each stream's decoding into one line and one
JSON object (from the wire's own encoders), a malformed message, following a log file as it is
written, the logs of an output directory, and the one-line refusals without a run.

Against a real `swarm up` (slow): a realtime case 2 whose followers fly a law of the test's
own that writes a line to the agent's log now and then; `swarm echo` of the ground truth, an
agent's frames and commands (text and --json); `swarm logs 3 --follow` as a process, printing
agent 3's lines as they come and ending with the run; `swarm echo events --json` as a process,
seeing the `stop` event; strangers (no credentials, forged ones, an agent's file) refused in
one line while the run goes on; then `swarm stop`: the run ends as on Ctrl-C (swarm up exits
130, summary.json `completed` false, `stopped_by_signal` 2, a `stop` event naming who asked).
"""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path

import numpy as np
import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, start_up, swarm_cmd, wait_for
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts import credentials, wire
from swarm.contracts.errors import UsageError
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.vocabulary import ExitCode
from swarm.live import client
from swarm.live import logs as L
from swarm.live.tap import Message, Tap, Topic, parse_topic


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


# -- keys ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name,leaf,agent",
    [
        ("truth", "truth", None),
        ("events", "events", None),
        ("world/control", "control", None),
        ("control", "control", None),
        ("agent/3/sense", "sense", "3"),
        ("agent/3/cmd", "cmd", "3"),
        ("agent/*/cmd", "cmd", "*"),
        ("agent/0/status", "status", "0"),
        ("/agent/12/ctl/", "ctl", "12"),
    ],
)
def test_keys_taken(name, leaf, agent):
    t = parse_topic(name)
    assert (t.leaf, t.agent) == (leaf, agent)
    key = t.key("r1")
    assert key.startswith("swarm/r1/") and wire.run_of_key(key) == "r1"


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,words",
    [
        ("bogus", "unknown key 'bogus'"),
        ("agent/3/join", "unknown key 'agent/3/join'"),
        ("agent/x/cmd", "'x' is not an agent id"),
        ("agent/03/cmd", "'03' is not an agent id"),
        ("agent/99999999999/cmd", "is not an agent id"),
        ("world/admin", "unknown key 'world/admin'"),
    ],
)
def test_bad_keys_refused_in_one_line_naming_them(name, words):
    with pytest.raises(UsageError) as e:
        parse_topic(name)
    assert words in str(e.value) and "\n" not in str(e.value)
    res = invoke("echo", name)
    assert res.exit_code == ExitCode.USAGE
    assert words in one_line(res.stderr)


# -- decoding ----------------------------------------------------------------------------------------
class _Ref:
    run = "r1"


class _Live:
    ref = _Ref()


def _tap(leaf: str, agent: str | None = None) -> Tap:
    return Tap(_Live(), Topic(leaf, leaf, agent))


def _check(m: Message, key: str) -> dict:
    assert m.error is None, m.error
    assert "\n" not in m.line()
    doc = json.loads(m.json())
    assert doc["key"] == key
    return doc


def test_truth_decoded():
    buf = wire.encode_truth(
        7, 0.07, [1, 2], [1.5, -2.0], [0.0, 3.25], [0.1, 0.2], [0.5, -0.5], [-1, 1], ["active", "gone"]
    )
    m = _tap("truth").decode("swarm/r1/truth", buf)
    doc = _check(m, "swarm/r1/truth")
    assert doc["tick"] == 7 and doc["time"] == 0.07
    assert doc["agents"] == [
        {"id": 1, "x": 1.5, "y": 0.0, "heading": 0.1, "u": 0.5, "out": None, "state": "active"},
        {"id": 2, "x": -2.0, "y": 3.25, "heading": 0.2, "u": -0.5, "out": 1, "state": "gone"},
    ]
    assert m.line().startswith("tick 7 t=0.070 | 1 (1.50, 0.00)") and "out=1 gone" in m.line()


def test_sense_and_cmd_decoded_without_the_claim_key():
    frame = SensorFrame(5, 0.05, 3, 1.0, (Contact(1, 0.5, 0.25, 30.0, 0), Contact(4, -0.5, 0.0, 12.5, -1)), None)
    doc = _check(
        _tap("sense", "3").decode("swarm/r1/agent/3/sense", wire.encode_sense(frame)), "swarm/r1/agent/3/sense"
    )
    assert doc["agent"] == 3 and doc["tick"] == 5 and doc["target"] is None
    assert [c["id"] for c in doc["contacts"]] == [1, 4] and doc["contacts"][1]["hops"] is None
    lead = frame._replace(target=(3.0, -4.0), contacts=())
    m = _tap("sense", "3").decode("k", wire.encode_sense(lead))
    assert m.data is not None and m.data["target"] == [3.0, -4.0] and "target=(3.00, -4.00) contacts 0" in m.line()
    cmd = wire.Command(3, 5, 0.25, 1, "track", 2, key=123456789)
    m = _tap("cmd", "3").decode("swarm/r1/agent/3/cmd", wire.encode_cmd(cmd))
    doc = _check(m, "swarm/r1/agent/3/cmd")
    assert doc == {
        "key": "swarm/r1/agent/3/cmd",
        "agent": 3,
        "tick": 5,
        "u": 0.25,
        "out": 1,
        "phase": "track",
        "hops": 2,
    }
    assert "123456789" not in m.line() + m.json()
    assert m.line() == "agent 3 tick 5 u=0.2500 out=1 phase=track hops=2"


def test_events_control_status_ctl_decoded():
    ev = {
        "tick": 3,
        "time": 0.03,
        "agent": 2,
        "kind": "switch",
        "reason": "out-neighbour chosen",
        "from": None,
        "to": 4,
    }
    m = _tap("events").decode("swarm/r1/events", wire.encode_event(ev))
    assert _check(m, "swarm/r1/events")["to"] == 4
    assert m.line() == "tick 3 t=0.030 switch agent 2: out-neighbour chosen from=null to=4"
    m = _tap("control").decode("swarm/r1/world/control", wire.encode_end(99))
    assert _check(m, "swarm/r1/world/control") == {"key": "swarm/r1/world/control", "kind": "end", "tick": 99}
    assert m.line() == "end at tick 99"
    m = _tap("control").decode("k", wire.encode_fault_notice(0, 50, {"kind": "kill", "agent": 3}))
    assert m.line() == "fault 0 at tick 50: kill agent 3"
    st = {"id": 3, "role": "follower", "out": 1, "hops": 1, "rooted": True}
    m = _tap("status", "3").decode("k", wire.encode_status(st))
    assert json.loads(m.line()) == st
    m = _tap("ctl", "3").decode("k", wire.encode_ctl("TERM"))
    assert m.line() == "signal TERM" and json.loads(m.json())["signal"] == "TERM"


@pytest.mark.parametrize("leaf", ["truth", "events", "control", "sense", "cmd", "status", "ctl"])
def test_malformed_message_said_not_raised(leaf):
    m = _tap(leaf, "3").decode("swarm/r1/x", b"\x00garbage")
    assert m.data is None and m.error
    assert m.line().startswith("malformed message on swarm/r1/x: ")
    assert set(json.loads(m.json())) == {"key", "error"}


def test_truth_with_a_nan_is_malformed():
    buf = wire.encode_truth(1, 0.01, [1], [math.nan], [0.0], [0.0], [0.0], [-1], ["active"])
    assert _tap("truth").decode("k", buf).data is None


# -- logs --------------------------------------------------------------------------------------------
def test_log_sources():
    assert L.parse_source("world") == "world" and L.parse_source("WORLD") == "world"
    assert L.parse_source("3") == "3" and L.parse_source("0") == "0" and L.parse_source(None) is None
    for bad in ("03", "-1", "agent", "3.0"):
        with pytest.raises(UsageError):
            L.parse_source(bad)
    res = invoke("logs", "fred")
    assert res.exit_code == ExitCode.USAGE and "'fred': give an agent id or `world`" in one_line(res.stderr)


@pytest.mark.slow
def test_follow_prints_lines_as_written_and_the_last_one_at_the_end(tmp_path):
    log = tmp_path / "agent-3.log"
    log.write_text("old 1\nold 2\nhalf")
    text, offset = L.tail(log, 1)
    assert text == ["old 2"]
    seen: list[str] = []
    written = threading.Event()
    stop = threading.Event()

    def writer():
        with open(log, "a") as f:
            f.write(" done\n")
            f.flush()
            wait_for(lambda: "half done" in seen, DEADLINE, "the follower to print the first line")
            f.write("new 1\nnew 2\nno newline")
            f.flush()
        written.set()
        wait_for(lambda: "new 2" in seen, DEADLINE, "the follower to print the new lines")
        stop.set()

    t = threading.Thread(target=writer)
    t.start()
    for line in L.follow(log, offset, stop.is_set):
        seen.append(line)
    t.join()
    assert written.is_set()
    assert seen == ["half done", "new 1", "new 2", "no newline"]


@pytest.mark.slow
def test_logs_of_an_output_directory(tmp_path):
    logs = tmp_path / "run" / "logs"
    logs.mkdir(parents=True)
    (logs / "world.log").write_text("w1\nw2\n")
    (logs / "agent-10.log").write_text("a10\n")
    (logs / "agent-2.log").write_text("a2 one\na2 two\n")
    (logs / "forkserver.log").write_text("")
    res = invoke("logs", "--out", tmp_path / "run")
    assert res.exit_code == ExitCode.OK, res.output
    assert [ln.split()[0] for ln in res.stdout.splitlines()] == ["world", "2", "10"]
    res = invoke("logs", "2", "--out", tmp_path / "run", "-n", "1")
    assert res.exit_code == ExitCode.OK and res.stdout == "a2 two\n"
    res = invoke("logs", "7", "--out", tmp_path / "run")
    assert res.exit_code == ExitCode.FAILED and "no log of agent 7" in one_line(res.stderr)
    res = invoke("logs", "world", "--out", tmp_path)
    assert res.exit_code == ExitCode.USAGE and "no logs/ there" in one_line(res.stderr)


@pytest.mark.parametrize("args", [["logs", "3"], ["stop"], ["echo", "truth"]])
def test_no_run_refused_in_one_line(args, tmp_path, monkeypatch):
    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(tmp_path))
    monkeypatch.delenv("SWARM_CREDENTIALS", raising=False)
    res = invoke(*args)
    assert res.exit_code == ExitCode.FAILED
    assert "no swarm is running" in one_line(res.stderr)


# -- against a real swarm up -----------------------------------------------------------------------------
CHATTY = """
import sys

def law(obs):
    if obs.tick % 20 == 0:
        print(f"chatty agent {obs.id} tick {obs.tick}", file=sys.stderr, flush=True)
    return obs.c2
"""


def chatty_scenario(d: Path) -> Path:
    """Case 2 whose followers fly `chatty` (loitering at c2, a line in their log every 20 ticks)."""
    d.mkdir()
    (d / "chatty.py").write_text(CHATTY)
    path = d / "case2-chatty.toml"
    path.write_text((SCENARIOS / "case2.toml").read_text() + '\n[law]\nfollower = "chatty:law"\n')
    return path


def chatty_lines(text: str) -> list[int]:
    return [int(ln.rsplit(" ", 1)[1]) for ln in text.splitlines() if ln.startswith("chatty agent 3 tick ")]


@pytest.mark.slow
def test_logs_echo_and_stop_against_swarm_up(rt, tmp_path, monkeypatch):
    monkeypatch.setenv("SWARM_RUNTIME_DIR", rt.dir)
    monkeypatch.delenv("SWARM_CREDENTIALS", raising=False)
    monkeypatch.delenv("SWARM_RUN", raising=False)
    monkeypatch.delenv("SWARM_CONNECT", raising=False)
    out = tmp_path / "run"
    up = start_up(rt.tracker, chatty_scenario(tmp_path / "sc"), out, "--clock", "realtime", "--duration", "300")
    up.wait_started(DEADLINE)
    run, endpoint = up.banner()
    ids = [1, 2, 3, 4, 5, 6]

    # echo: the ground truth, an agent's frames and commands (text and JSON), one line each
    res = invoke("echo", "truth", "--count", "3", "--json")
    assert res.exit_code == ExitCode.OK, res.output
    docs = [json.loads(ln) for ln in res.stdout.splitlines()]
    assert len(docs) == 3 and all(d["key"] == f"swarm/{run}/truth" for d in docs)
    assert [a["id"] for a in docs[0]["agents"]] == ids
    assert docs[0]["tick"] < docs[1]["tick"] < docs[2]["tick"]
    res = invoke("echo", "truth", "-c", "1")
    assert res.exit_code == ExitCode.OK and one_line(res.stdout).startswith("tick ")
    res = invoke("echo", "agent/3/sense", "-c", "2")
    assert res.exit_code == ExitCode.OK, res.output
    assert all(ln.startswith("agent 3 tick ") and " contacts " in ln for ln in res.stdout.splitlines())
    assert len(res.stdout.splitlines()) == 2
    res = invoke("echo", "agent/3/cmd", "-c", "2", "--json")
    assert res.exit_code == ExitCode.OK, res.output
    for d in map(json.loads, res.stdout.splitlines()):
        assert set(d) == {"key", "agent", "tick", "u", "out", "phase", "hops"} and d["agent"] == 3
        assert np.isfinite(d["u"])
    res = invoke("echo", "agent/*/cmd", "-c", "12", "--json")
    assert {json.loads(ln)["agent"] for ln in res.stdout.splitlines()} <= set(ids)
    res = invoke("echo", "agent/3/status", "-c", "1", "--json")
    assert res.exit_code == ExitCode.OK and json.loads(res.stdout)["id"] == 3

    # logs: the list, then agent 3's lines as they are written (a process following them)
    res = invoke("logs")
    assert res.exit_code == ExitCode.OK, res.output
    listed = dict(ln.split() for ln in res.stdout.splitlines())
    assert listed["world"] == str(out.resolve() / "logs" / "world.log") and set(map(str, ids)) <= set(listed)
    res = invoke("logs", "9")
    assert res.exit_code == ExitCode.FAILED and "agent 9 is not in run" in one_line(res.stderr)
    follower = rt.tracker.spawn(swarm_cmd("logs", "3", "--follow", "--tail", "0"), "logs-follow")
    events = rt.tracker.spawn(swarm_cmd("echo", "events", "--json"), "echo-events")
    first = wait_for(lambda: chatty_lines(follower.text()), DEADLINE, "swarm logs --follow to print agent 3's lines")
    wait_for(
        lambda: len(chatty_lines(follower.text())) > len(first) + 1, DEADLINE, "more of agent 3's lines as written"
    )
    got = chatty_lines(follower.text())
    assert got == sorted(got) and got[-1] > got[0]

    # strangers: no credentials, forged ones, an agent's file: one line each, and the run goes on
    empty = tmp_path / "empty-rt"
    empty.mkdir(mode=0o700)
    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(empty))
    for args in (["stop"], ["echo", "truth"], ["logs", "3"]):
        res = invoke(*args, "--connect", endpoint)
        assert res.exit_code == ExitCode.FAILED and "no swarm is running" in one_line(res.stderr)
    own = credentials.read(Path(rt.dir) / f"{run}{credentials.SUFFIX}")
    forged = credentials.write(credentials.new_credentials(run, own.endpoint), tmp_path / "forged.cred")
    with monkeypatch.context() as mp:  # the hub's refusal is waited out for 1 s, not the 3 s of OPEN_TIMEOUT_S
        real = client._probe
        mp.setattr(client, "_probe", lambda ref, timeout=0.5, open_timeout=1.0: real(ref, timeout, open_timeout))
        res = invoke("stop", "--credentials", forged)
    assert res.exit_code == ExitCode.FAILED and one_line(res.stderr)
    agent_file = credentials.write(own.export("agent-3"), tmp_path / "agent3.cred")
    res = invoke("echo", "truth", "-c", "1", "--credentials", agent_file)
    assert res.exit_code == ExitCode.FAILED and one_line(res.stderr)
    monkeypatch.setenv("SWARM_RUNTIME_DIR", rt.dir)
    up.running("the strangers to be refused")
    t0 = up.info()["tick"]
    wait_for(lambda: up.info()["tick"] > t0, DEADLINE, "the run to go on")

    # the tap of the events hears them: a pause and a resume (so it listens before the stop)
    assert invoke("pause").exit_code == ExitCode.OK and invoke("resume").exit_code == ExitCode.OK
    wait_for(lambda: '"kind":"resume"' in events.text(), DEADLINE, "swarm echo events to print the pause and resume")

    # stop: as Ctrl-C, from here
    res = invoke("stop")
    assert res.exit_code == ExitCode.OK, res.output
    line = one_line(res.stdout)
    assert line.startswith(f"run {run} stopped at tick ") and line.endswith(f"results in {out.resolve()}")
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    assert "the run was stopped from another terminal (asked by swarm stop (" in up.launcher.text()
    summary = up.summary()
    assert summary["completed"] is False and summary["stopped_by_signal"] == 2
    stops = [e for e in summary["events"] if e["kind"] == "stop"]
    assert len(stops) == 1 and stops[0]["agent"] is None and stops[0]["reason"].startswith("asked by swarm stop (")
    assert stops[0]["tick"] == int(line.split(" tick ")[1].split(";")[0])

    # the follower and the tap ended with the run, having seen it all
    assert follower.wait(DEADLINE) == ExitCode.OK
    assert events.wait(DEADLINE) == ExitCode.OK
    seen = [json.loads(ln) for ln in events.text().splitlines() if ln.startswith("{")]
    # (a loaded machine may stall the realtime world meanwhile: its `late` events are not the point)
    assert [d["kind"] for d in seen if d["kind"] != "late"][-3:] == ["pause", "resume", "stop"]
    assert all(d["key"] == f"swarm/{run}/events" for d in seen)
    whole = chatty_lines((out / "logs" / "agent-3.log").read_text())
    assert chatty_lines(follower.text()) == [t for t in whole if t >= first[0]]

    # a finished run's logs, from its output directory
    res = invoke("logs", "3", "--out", out)
    assert res.exit_code == ExitCode.OK and chatty_lines(res.stdout) == whole
    res = invoke("logs", "world", "--out", out, "-n", "5")
    assert res.exit_code == ExitCode.OK and len(res.stdout.splitlines()) == 5
