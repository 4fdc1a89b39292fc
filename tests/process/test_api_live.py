"""The live API (`swarm.connect`, `swarm.runs`: swarm/api/live.py) and the one place its errors
become exit codes (swarm/cli/errors.py). Offline: the error classes, their codes, and what a
live command's process imports. Against a live run: case2 under `swarm up` (real processes,
real zenoh) in a private runtime dir, read and acted on through the API, and the same answers
as the commands print.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, live_swarm, short_runtime_dir, swarm_cmd
from typer.testing import CliRunner

import swarm
from swarm.cli.errors import exit_code


def test_error_classes_and_their_exit_codes():
    from swarm.contracts.scenario import ScenarioError
    from swarm.offline.results import OutDirError
    from swarm.plots import PlotError
    from swarm.world.run_reader import RunReadError
    from swarm.world.stream import RecordingError

    assert issubclass(swarm.NoRunError, swarm.SwarmError) and issubclass(swarm.UpError, RuntimeError)
    assert issubclass(swarm.UsageError, ValueError)
    from swarm.live.client import NoRun

    assert NoRun is swarm.NoRunError  # what swarm/live/client.py raises is the API's class
    codes = {
        swarm.NoRunError: 1,
        swarm.LiveError: 1,
        swarm.UsageError: 2,
        swarm.UpError: 1,
        ScenarioError: 2,
        OutDirError: 2,
        RunReadError: 1,
        PlotError: 1,
        RecordingError: 74,
    }
    assert {cls: exit_code(cls("x")) for cls in codes} == codes
    assert exit_code(ValueError("x")) is None and exit_code(KeyError(3)) is None  # bugs keep their traceback


def test_a_watcher_tells_a_world_that_ended_from_one_that_stopped_answering(monkeypatch):
    """Live.again: the last reading while the world misses reads; NoRunError at once when it is
    gone (its end notice, its endpoint refusing); StoppedAnswering (a NoRunError, exit 1 too)
    after ENDED_FAILURES failed reads over ENDED_SILENT_S s of a world that is still there."""
    import swarm.live.client as live_mod
    from swarm.api.live import Live

    class FakeRun:
        gone_now = False

        def watch_end(self):
            pass

        def gone(self):
            return self.gone_now

        ref = live_mod.RunRef("r1", "unixsock-stream//nowhere")

    def fails():
        raise swarm.NoRunError("the world did not answer")

    monkeypatch.setattr(live_mod, "ENDED_SILENT_S", 0.0)
    fake = FakeRun()
    live = Live(fake)
    assert live.again(lambda: 5, 0) == 5
    assert live.again(fails, 5) == 5 and live.again(fails, 5) == 5  # two misses: the last reading
    with pytest.raises(swarm.StoppedAnswering, match="the world of run r1 stopped answering"):
        live.again(fails, 5)
    assert issubclass(swarm.StoppedAnswering, swarm.NoRunError) and exit_code(swarm.StoppedAnswering("x")) == 1

    fake.gone_now = True
    live = Live(fake)
    with pytest.raises(swarm.NoRunError) as e:
        live.again(fails, 5)  # gone: ended at once, not "stopped answering"
    assert not isinstance(e.value, swarm.StoppedAnswering)


def test_a_one_shot_read_asks_a_world_that_missed_a_query_again(monkeypatch):
    """Live.info / agents (a script's one read, README's `live.agents()`): a world that is there
    but missed a query's time (a loaded machine) is asked again, as a watcher would; NoRunError
    at once when it is gone, and after ENDED_FAILURES misses over ENDED_SILENT_S when it stays
    silent. Inside a watching loop (`again`) a read is one query: the loop's patience decides."""
    import swarm.live.client as live_mod
    from swarm.api.live import Live

    class FakeRun:
        ref = live_mod.RunRef("r1", "unixsock-stream//nowhere")
        gone_now = False
        misses = 0  # queries this world misses before it answers
        asked = 0

        def watch_end(self):
            pass

        def gone(self):
            return self.gone_now

        def info(self, sensing=False):
            self.asked += 1
            if self.asked <= self.misses:
                raise swarm.NoRunError(f"the world of run {self.ref.run} did not answer (it may have ended)")
            return {"tick": 7, "sensing": sensing}

    monkeypatch.setattr(live_mod, "ENDED_SILENT_S", 0.0)
    fake = FakeRun()
    fake.misses = 2
    assert Live(fake).info() == {"tick": 7, "sensing": False} and fake.asked == 3  # two misses, asked again

    fake = FakeRun()
    fake.misses = 1
    live = Live(fake)
    assert live.again(live.info, "last") == "last" and fake.asked == 1  # a watcher's read: one query
    assert live.again(live.info, "last") == {"tick": 7, "sensing": False}

    fake = FakeRun()
    fake.misses, fake.gone_now = 10, True
    with pytest.raises(swarm.NoRunError):
        Live(fake).info()
    assert fake.asked == 1  # ended: not asked again

    fake = FakeRun()
    fake.misses = 10
    with pytest.raises(swarm.NoRunError, match="did not answer"):
        Live(fake).info()
    assert fake.asked == live_mod.ENDED_FAILURES  # silent: given up after the watchers' patience


@pytest.fixture
def empty_runtime(monkeypatch):
    import shutil

    d = short_runtime_dir()
    monkeypatch.setenv("SWARM_RUNTIME_DIR", d)
    monkeypatch.delenv("SWARM_RUN", raising=False)
    monkeypatch.delenv("SWARM_CONNECT", raising=False)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def test_connect_without_a_run_raises_one_line(empty_runtime, monkeypatch):
    with pytest.raises(swarm.NoRunError, match=r"^no swarm is running: looked at local runs in "):
        swarm.connect()
    with pytest.raises(swarm.NoRunError, match=r"^run 'case2-ffffff' not found: looked at local runs in "):
        swarm.connect(run="case2-ffffff")
    monkeypatch.setenv("SWARM_RUN", "case2-eeeeee")  # the default run, as the commands' --run
    with pytest.raises(swarm.NoRunError, match="run 'case2-eeeeee' not found"):
        swarm.connect()
    with pytest.raises(swarm.NoRunError, match="run id"):
        swarm.connect(run="no/such run")
    assert swarm.runs() == []


@pytest.mark.slow
def test_a_live_command_process_imports_only_its_group(empty_runtime):
    """`swarm pause` as a process: no scenario model, no numpy, none of the other command groups."""
    code = (
        "import sys; sys.argv = ['swarm', 'pause']\nfrom swarm.cli.main import main\ntry:\n    main()\n"
        "except SystemExit as e:\n    code = e.code\n"
        "print(sorted(m for m in sys.modules if m.startswith(('swarm.', 'numpy', 'world')) or m == 'numpy'),"
        " code)"
    )
    p = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=DEADLINE,
        env={**os.environ, "SWARM_RUNTIME_DIR": empty_runtime},
    )
    assert "no swarm is running" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    mods, rc = p.stdout.rsplit(" ", 1)
    assert rc.strip() == "1"
    for heavy in (
        "numpy",
        "swarm.contracts.scenario",
        "swarm.cli.up",
        "swarm.cli.run",
        "swarm.cli.study",
        "swarm.cli.offline",
        "swarm.api.runs",
        "swarm.world.recording",
    ):
        assert f"'{heavy}'" not in mods, (heavy, mods)


# --- against a live run ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def live(tmp_path_factory):
    with live_swarm(tmp_path_factory.mktemp("apilive"), SCENARIOS / "case2.toml", 6, "--duration", "600") as state:
        yield state


def _cli_json(*args):
    from swarm.cli.main import app

    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.mark.slow
def test_connect_reads_agents_graph_and_state(live):
    assert [d["run"] for d in swarm.runs()] == [live["run"]]
    with swarm.connect() as lv:  # the only run: no arguments needed
        assert (lv.run, lv.endpoint) == (live["run"], live["endpoint"])
        rows = lv.agents()
        assert [r["id"] for r in rows] == [1, 2, 3, 4, 5, 6] and all(r["alive"] and r["answered"] for r in rows)
        assert {r["id"] for r in rows if r["role"] == "leader"} == {1, 6}
        g = lv.graph()
        assert g["run"] == live["run"] and g["nodes"] == [1, 2, 3, 4, 5, 6] and g["leaders"] == [1, 6]
        assert set(g) == set(_cli_json("graph", "--json"))  # the document `swarm graph --json` prints
        state = lv.state()
        assert sorted(state.agents) == [1, 2, 3, 4, 5, 6] and state.agents[1].role == "leader"
        assert set(state.poses) == {1, 2, 3, 4, 5, 6} and state.graph["leaders"] == [1, 6]
        info = lv.info(sensing=True)
        assert info["run"] == live["run"] and "sensing" in info
    with swarm.connect(run=live["run"], connect=live["endpoint"]) as lv:
        assert lv.run == live["run"]


@pytest.mark.slow
def test_connect_pauses_resumes_and_refuses_what_it_cannot_do(live):
    with swarm.connect(live["run"]) as lv:
        tick = lv.pause()
        assert isinstance(tick, int) and lv.info()["paused"] is True
        assert lv.pause() == tick  # paused already: no error, the same tick
        assert _cli_json("agents", "--json")["paused"] is True
        assert lv.resume() == tick and lv.info()["paused"] is False
        with pytest.raises(swarm.LiveError, match=r"^agent 99 is not in run .* \(ids: 1, 2, 3, 4, 5, 6\)$"):
            lv.signal(99)
        with pytest.raises(swarm.UsageError, match="--signal 'HUP': use one of KILL, TERM, STOP, CONT"):
            lv.kill(3, "HUP")
        with pytest.raises(swarm.UsageError, match="only apply to a new id"):
            lv.spawn(3, x=1.0)  # a known id rejoins: no spec
        with pytest.raises(swarm.UsageError, match=r"invalid spec.*a new agent needs --x --y --heading --speed"):
            lv.spawn(7, x=1.0)
        assert all(r["alive"] for r in lv.agents())  # nothing was started or signalled


@pytest.mark.slow
def test_commands_exit_with_the_api_errors_codes(live):
    """The same refusals through the commands, as processes: one line, the class's exit code."""
    for args, code, what in (
        (["kill", "99"], 1, "agent 99 is not in run"),
        (["spawn", "--id", "3", "--x", "1"], 2, "only apply to a new id"),
        (["kill", "3", "--signal", "HUP"], 2, "use one of KILL"),
    ):
        p = subprocess.run(swarm_cmd(*args), capture_output=True, text=True, timeout=DEADLINE, stdin=subprocess.DEVNULL)
        assert p.returncode == code and what in p.stderr, (args, p.returncode, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr, p.stderr
