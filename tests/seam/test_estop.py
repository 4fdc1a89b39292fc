"""The e-stop's own logic (swarm/api/estop.py, swarm/cli/estop_first.py) with a fake Halt and
no zenoh: what it does when its output is gone, what it says of a world that does not answer,
and what `swarm estop`'s first zero twists leave behind when the command ends early. The
e-stop on real robots' networks: tests/process/test_robots_stops.py."""

from __future__ import annotations

import importlib
import threading
from types import SimpleNamespace

import pytest

from swarm.api import estop as api
from swarm.cli import estop_first
from swarm.contracts.errors import NoRunError


class FakeHalt:
    """A Halt (swarm/robots/halt.py) that counts what it is asked to do."""

    def __init__(self, plan=None, **_):
        self.plan = plan if plan is not None else SimpleNamespace(connect="tcp/127.0.0.1:7447", targets=())
        self.first_sent: float | None = None
        self.robots = 2
        self.zeros = 0
        self.closed = False
        self.lock = threading.Lock()

    def zero(self, repeat: int = 3, **_) -> int:
        with self.lock:
            self.zeros += 1
        return 0 if self.closed else 2

    def close(self) -> None:
        self.closed = True


def test_a_closed_output_does_not_keep_the_run_from_ending(monkeypatch):
    """`say` (the CLI's first line) raising (stdout a closed pipe) left the run running (the world
    drove the robots again once the zero twists stopped) and the robots' session open."""
    ended = []
    monkeypatch.setattr(api, "end_run", lambda *a, **k: ended.append(a) or ("r1", "run r1 stopped at tick 9"))
    halt = FakeHalt()

    def say(line: str) -> None:
        raise BrokenPipeError(32, "Broken pipe")

    done = api.estop(say=say, sent_first=(None, halt, 2, 0.001))
    assert ended and done.run == "r1" and done.ended == "run r1 stopped at tick 9"
    assert halt.closed and halt.zeros >= 1  # the last zero twists, then closed


def test_a_world_that_does_not_answer_is_not_said_to_be_gone(monkeypatch):
    """A world alive whose run cannot be reached (refused, several runs, busy): the line said
    "its world was gone"; it says why it did not answer."""
    import swarm.live.client as client

    def no_run(*_a, **_k):
        raise NoRunError("run r1: credentials refused")

    monkeypatch.setattr(client, "open_run_session", no_run)
    monkeypatch.setattr(api, "_alive", lambda pid: True)
    monkeypatch.setattr(api, "_stopped_child", lambda pid, parent: False)
    record = SimpleNamespace(run="r1", world_pid=1_000_001, launcher_pid=1_000_000)
    run, line = api.end_run(record, None, None, None, timeout=0.01)  # type: ignore[arg-type]
    assert run == "r1" and line is not None
    assert "its world did not answer (run r1: credentials refused)" in line and "gone" not in line, line
    monkeypatch.setattr(api, "_alive", lambda pid: pid == 1_000_000)  # the world gone: said so
    run, line = api.end_run(record, None, None, None, timeout=0.01)  # type: ignore[arg-type]
    assert line is not None and "its world is gone" in line, line


def test_the_first_zero_twists_are_closed_when_the_command_ends_before_taking_them(monkeypatch):
    """`swarm estop` sends zero twists before the command line loads (estop_first.first); a
    command that then ends early (a usage error, a stop) never took them: their hold thread and
    session were left to the interpreter's end (a zenoh session open at exit can abort it).
    An exit handler now stops and closes them."""
    made: list[FakeHalt] = []

    def fake_halt(plan, **kw):
        made.append(FakeHalt(plan, **kw))
        return made[-1]

    record = SimpleNamespace(run="r1", plan=SimpleNamespace(connect="tcp/127.0.0.1:7447", targets=()))
    halt_mod = importlib.import_module("swarm.robots.halt")
    monkeypatch.setattr(halt_mod, "Halt", fake_halt)
    for name in ("swarm.robots.run_record", "swarm.robots.halt"):
        try:
            mod = importlib.import_module(name)
        except ImportError:
            continue
        if hasattr(mod, "find_record"):
            monkeypatch.setattr(mod, "find_record", lambda run: record)
    registered: list = []
    monkeypatch.setattr(estop_first.atexit, "register", registered.append)
    estop_first.first(["--run", "r1"])
    try:
        assert len(made) == 1 and made[0].zeros == 1 and not made[0].closed
        assert registered, "nothing closes the first zero twists' session at exit"
        for handler in registered:
            handler()
        assert made[0].closed and estop_first.taken() is None
    finally:
        estop_first.taken()  # whatever the test left: the hold thread stopped
    registered.clear()
    estop_first.first(["--ready"])  # nothing sent here: nothing to close
    assert not registered and len(made) == 1


@pytest.mark.parametrize("args", [["--help"], ["--robots", "r.toml"], ["--robots=r.toml"]])
def test_the_first_zero_twists_leave_the_command_what_it_does_itself(args, monkeypatch):
    registered: list = []
    monkeypatch.setattr(estop_first.atexit, "register", registered.append)
    estop_first.first(args)
    assert estop_first.taken() is None and not registered


def test_a_stalled_world_killed_meanwhile_is_no_traceback(monkeypatch):
    """The world seen stopped (SIGSTOP), then gone before the SIGKILL (its swarm up ended it
    meanwhile): os.kill raised ProcessLookupError out of `swarm estop`, a traceback."""

    def kill(pid, sig):
        raise ProcessLookupError(3, "No such process")

    monkeypatch.setattr(api, "_stopped_child", lambda pid, parent: True)
    monkeypatch.setattr(api, "_alive", lambda pid: pid == 1_000_000)
    monkeypatch.setattr(api.os, "kill", kill)
    monkeypatch.setattr(api, "_wait_gone", lambda pid, timeout: True)
    record = SimpleNamespace(run="r1", world_pid=1_000_001, launcher_pid=1_000_000)
    run, line = api.end_run(record, None, None, None, timeout=0.01)  # type: ignore[arg-type]
    assert run == "r1" and line is not None and "has ended the run" in line, line
