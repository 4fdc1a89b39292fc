"""`swarm.connect(...)` and `swarm.runs(...)`: a live run from Python, as the live commands
see it (`swarm agents / graph / pause / resume / kill / spawn / runs / watch / logs / stop / echo`
are made of these; docs/reference/cli.md#live has the shapes of what they return).

    with swarm.connect() as live:               # the only local run (or run=ID, connect=EP, credentials=FILE)
        rows = live.agents()                    # `swarm agents --json`'s rows
        g = live.graph()                        # `swarm graph --json`'s document
        live.pause(); live.resume()             # the tick the world stopped / went on at
        live.kill(3)                            # SIGKILL, then the tick the world dropped it at
        for m in live.echo("events", count=5):  # `swarm echo events --json`'s objects (m.data)
            ...
        live.stop()                             # end the run as Ctrl-C of its `swarm up` does

Everything goes over zenoh (swarm/live/client.py), so a run on another machine works the same
with its credentials. What cannot be done raises one of swarm/contracts/errors.py's classes, one
line each: `NoRunError` (no run, or its world stopped answering), `LiveError` (an unknown
agent, a spawned agent that did not join...), `UsageError` (a bad argument).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from swarm.api.record import Record
from swarm.contracts.errors import LiveError, NoRunError, StoppedAnswering, UsageError
from swarm.live.client import ENDED_SILENT_S, LiveRun, Patience, find_runs, open_run_session, talking

__all__ = ["Live", "LiveState", "connect", "runs"]

ENV_RUN = "SWARM_RUN"  # the default run id of swarm.connect and the live commands
ENV_CONNECT = "SWARM_CONNECT"  # their default endpoint


def _env(value: str | None, name: str) -> str | None:
    """`value`, else the variable `name` (an empty one counts as unset)."""
    return value if value is not None else (os.environ.get(name) or None)


def _endpoint(value: str | None) -> str | None:
    """`connect=` (else $SWARM_CONNECT), checked: UsageError "not an endpoint: ..." (one line)."""
    # lazy: every command imports this module (swarm/cli/options.py); `swarm --help` starts without this one
    from swarm.contracts.endpoints import EndpointError, check_endpoint

    ep = _env(value, ENV_CONNECT)
    try:
        return None if ep is None else check_endpoint(ep, what="connect")
    except EndpointError as e:
        raise UsageError(str(e)) from None


class LiveState(Record):
    """One reading of a live run: `tick`, `time`, `started`, `paused`, `agents` (by int id:
    role, alive, x, y, heading, out, root, hops, radial_error...: the rows of `swarm
    agents`), `graph` (`swarm graph --json`'s document) and `info` (the world's as it came)."""

    @property
    def poses(self) -> dict[int, tuple[float, float, float]]:
        """(x, y, heading) of every agent, by id."""
        return {aid: (a["x"], a["y"], a["heading"]) for aid, a in self.agents.items()}


class Live:
    """An open session to one live run (`swarm.connect`); close it, or use it in a `with`
    block. `run` and `endpoint` say which run it is."""

    def __init__(self, lr):
        self._lr = lr  # a swarm.live.client.LiveRun, open
        self._patience = None
        self._watching = False  # inside a watching loop's read (`again`)

    @property
    def run(self) -> str:
        return self._lr.ref.run

    @property
    def endpoint(self) -> str:
        return self._lr.ref.endpoint

    @property
    def ref(self):
        """The run's `swarm.live.client.RunRef` (run id, endpoint, credentials)."""
        return self._lr.ref

    def close(self) -> None:
        self._lr.__exit__(None, None, None)

    def __enter__(self) -> Live:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Live(run {self.run!r} on {self.endpoint})"

    # -- reading ----------------------------------------------------------------------------------
    def info(self, sensing: bool = False) -> dict:
        """The world's info: tick, clock, paused, and per agent pose, state, out, errors...
        (`sensing`: who senses whom too)."""
        return self._patiently(lambda: self._lr.info(sensing=sensing))

    def statuses(self, expected: Iterable[int] | None = None) -> dict[int, dict]:
        """Each live agent's own status by id (ends once every id of `expected` answered)."""
        with talking():
            return self._lr.statuses(expected)

    def snapshot(self, sensing: bool = False) -> dict:
        """{"info": the world's info, "agents": the merged rows}, read now (swarm/live/data.py)."""
        # lazy: swarm.live.data (with contracts.graph) is for reading: `swarm pause` / `kill` start without it
        from swarm.live.data import snapshot

        return self._patiently(lambda: snapshot(self._lr, sensing))

    def _patiently(self, read: Callable[[], Any]) -> Any:
        """One read of the world, asked again while the world is there and has not stopped
        answering (`Patience`, the watchers' rule: a loaded world that misses one query's
        time is not an ended one); NoRunError once it has ended or stayed silent."""
        if self._watching:  # a watching loop's read (`again`): its own patience decides
            with talking():
                return read()
        patience: Patience | None = None
        while True:
            try:
                with talking():
                    return read()
            except NoRunError:
                patience = patience or Patience(self._lr)
                if patience.ended():
                    raise

    def agents(self) -> list[dict]:
        """One row per agent, sorted by id: `swarm agents --json`'s `agents`."""
        return self.snapshot()["agents"]

    def wait_joined(self, ids: Iterable[int] | None = None, timeout: float = 60.0) -> list[dict]:
        """Until every agent of `ids` (default: every agent the run has, dropped ones too: pass `ids`
        once some have dropped) has joined and is alive;
        the rows of `agents()` then. A run just started by `swarm up` answers before its agents
        have all joined: wait for them before killing one. LiveError after `timeout` s."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                rows = self.agents()
            except NoRunError:  # a world too busy to answer in time (a loaded machine): ask again
                if time.monotonic() > deadline:
                    raise
                continue
            want = set(ids) if ids is not None else {r["id"] for r in rows}
            ready = {r["id"] for r in rows if r.get("alive") and r.get("pid") is not None}
            if want <= ready:
                return rows
            if time.monotonic() > deadline:
                late = ", ".join(map(str, sorted(want - ready)))
                raise LiveError(f"agents {late} of run {self.run} had not joined after {timeout} s")
            time.sleep(0.05)

    def graph(self, sensing: bool = False) -> dict:
        """The communication graph: `swarm graph --json`'s document."""
        from swarm.live.data import graph_of  # lazy: as in `snapshot`

        return graph_of(self.snapshot(sensing), sensing)

    def state(self) -> LiveState:
        """The live run now, as a `LiveState` (agents, poses, graph)."""
        from swarm.live.data import graph_of  # lazy: as in `snapshot`

        snap = self.snapshot()
        info = snap["info"]
        return LiveState(
            {
                "run": info.get("run"),
                "tick": info.get("tick"),
                "time": info.get("time"),
                "started": info.get("started"),
                "paused": info.get("paused"),
                "agents": {int(r["id"]): r for r in snap["agents"]},
                "graph": graph_of(snap),
                "info": info,
            }
        )

    def gone(self) -> bool:
        """Whether the run has ended for sure: its world's end notice came (listened for from
        the first call on), or its endpoint refuses connections."""
        self._lr.watch_end()
        return self._lr.gone()

    def again(self, read, last):
        """`read()` of a watching loop (`swarm watch`, `swarm graph --watch`): its value, or
        `last` while the world does not answer; NoRunError once the world has ended for sure
        (its end notice, its endpoint refusing connections), StoppedAnswering (a NoRunError)
        after several failed reads over several seconds of a world that has not ended
        (`swarm.live.client.Patience`)."""
        if self._patience is None:
            self._patience = Patience(self._lr)
        self._watching = True
        try:
            value = read()
        except NoRunError:
            if not self._patience.ended():
                return last
            if self._patience.silent:
                raise StoppedAnswering(
                    f"the world of run {self.run} stopped answering for {ENDED_SILENT_S:g} s "
                    "or more without ending (stalled, starved, or cut off from here)"
                ) from None
            raise
        finally:
            self._watching = False
        self._patience.answered()
        return value

    # -- acting -----------------------------------------------------------------------------------
    def admin(self, cmd: str, by: str = "swarm cli") -> dict:
        """The world's reply to admin request `cmd` (NoRunError with the world's error if refused)."""
        with talking():
            return self._lr.admin(cmd, by=by)

    def pause(self) -> int | None:
        """Hold the world's clock; the tick it stopped at (no error if paused already)."""
        return self.admin("pause").get("tick")

    def resume(self) -> int | None:
        """Restart the world's clock; the tick it goes on from (no error if it runs)."""
        return self.admin("resume").get("tick")

    def stop(self, wait: bool = True, timeout: float | None = None):
        """End the run as Ctrl-C of its `swarm up` does (`swarm stop`): its results written,
        summary.json `completed` false and `stopped_by_signal` 2, a `stop` event; with `wait`,
        until it has ended (LiveError after `timeout` s). A `swarm.live.stop.Stopped` (tick, out)."""
        from swarm.live.stop import STOP_DEADLINE, stop_run  # lazy: swarm.runtime.procs (~4 ms), as in `spawn`

        with talking():
            return stop_run(self._lr, wait=wait, timeout=STOP_DEADLINE if timeout is None else timeout)

    def estop(self, robots: str | Path | None = None, end: bool = True):
        """Every robot of this run zero-twisted straight onto the robots' network, then the run
        ended (`swarm estop`; swarm/api/estop.py): `robots` the robots file (default: the run's
        record on this machine); `end` False leaves the run alone. A `swarm.Estopped`."""
        from swarm.api.estop import estop  # lazy: the robots' protocol, for an e-stop only

        return estop(robots=robots, end=end, live=self._lr)

    def echo(self, key: str, count: int | None = None):
        """The messages on `key` of the run (`truth`, `events`, `world/control`,
        `agent/<id>/sense|cmd|status|ctl`; `*` for every agent), decoded, as they come, until
        `count` of them or the run's end: `swarm.live.tap.Message`s (`data`: a dict as
        `swarm echo --json` prints it; `error` for a malformed one; `dropped`: messages lost
        just before it; a `note` first when the tap waits for an agent the run may still
        add). UsageError for an unknown key; LiveError for an agent the run cannot have."""
        from swarm.live.tap import parse_topic  # lazy: for a tap only; other live commands start without it

        return self._echo(parse_topic(key), count)  # an unknown key: at once, not at the first message

    def _echo(self, topic, count: int | None):
        from swarm.live.tap import Tap  # lazy: as in `echo`

        with talking(), Tap(self._lr, topic) as tap:
            yield from tap.messages(count)

    def logs(self):
        """The logs of the run's processes on this machine (`swarm logs`): a
        `swarm.live.logs.RunLogs` (`files()`, `path("world")`, `path("3")`); LiveError when
        they are on another machine or the world writes no results."""
        from swarm.live.logs import logs_of_info  # lazy: as in `echo`

        return logs_of_info(self.info())

    def signal(self, agent_id: int, signal: str = "KILL"):
        """Send `signal` (KILL, TERM, STOP, CONT) to agent `agent_id`'s process, without
        waiting: a `swarm.live.control.Signalled` (`drops`: whether the world is to drop it)."""
        from swarm.live.control import signal_agent  # lazy: swarm.runtime.procs (~4 ms), as in `spawn`

        with talking():
            return signal_agent(self._lr, agent_id, signal)

    def wait_dropped(self, done, timeout: float | None = None) -> int:
        """The tick the world dropped the agent `done` (from `signal`) at; LiveError after `timeout` s."""
        from swarm.live.control import DROP_DEADLINE, wait_dropped  # lazy: swarm.runtime.procs, as in `spawn`

        with talking():
            return wait_dropped(self._lr, done, DROP_DEADLINE if timeout is None else timeout)

    def kill(self, agent_id: int, signal: str = "KILL") -> int | None:
        """`signal`, then the tick the world dropped the agent at (None: no drop to wait for)."""
        done = self.signal(agent_id, signal)
        return self.wait_dropped(done) if done.drops else None

    def spawn(self, agent_id: int, trust_law: Iterable[str] = (), timeout: float | None = None, **spec):
        """Start agent `agent_id` on this machine and wait until it is live (LiveError after
        `timeout` s, default 10): a dropped id rejoins; a new one needs x, y, heading, speed
        (role, orbit_radius, direction, follow, max_turn_rate optional). A
        `swarm.live.control.Spawned` (pid, log)."""
        # lazy: swarm.live.control brings swarm.runtime.procs (~4 ms), and every command imports this module
        from swarm.live.control import SPAWN_DEADLINE, spawn_agent

        with talking():
            return spawn_agent(
                self._lr, agent_id, spec, tuple(trust_law), SPAWN_DEADLINE if timeout is None else timeout
            )


def connect(run: str | None = None, connect: str | None = None, credentials: str | Path | None = None) -> Live:
    """The live run `run` (default $SWARM_RUN, else the only one found) on endpoint `connect`
    (default $SWARM_CONNECT, else the local runs), with `credentials` (default
    $SWARM_CREDENTIALS, else the local runs' own files); NoRunError with one line if there
    is no such run, or several."""
    with talking():
        return Live(
            open_run_session(_endpoint(connect), _env(run, ENV_RUN), None if credentials is None else Path(credentials))
        )


def runs(run: str | None = None, connect: str | None = None, credentials: str | Path | None = None) -> list[dict]:
    """The live runs reachable (`swarm runs --json`'s documents, sorted as found); [] if none.
    A run that ends while it is asked is listed with what is known (its other fields None)."""
    creds = None if credentials is None else Path(credentials)
    with talking():
        found = find_runs(_endpoint(connect), creds, _env(run, ENV_RUN))
    docs = []
    for ref in found:
        doc: dict[str, Any] = {
            "run": ref.run,
            "endpoint": ref.endpoint,
            "scenario": None,
            "clock": None,
            "paused": None,
            "tick": None,
            "ticks": None,
            "time": None,
            "agents_live": None,
            "agents_total": None,
            "host": None,
            "pid": None,
        }
        try:
            with LiveRun(ref) as lr:
                info = lr.info()
            agents = info.get("agents", {})
            doc.update(
                {k: info.get(k) for k in ("scenario", "clock", "paused", "tick", "ticks", "time", "host", "pid")},
                agents_live=sum(1 for a in agents.values() if a.get("alive")),
                agents_total=len(agents),
            )
        except Exception:
            pass  # it ended between the two questions (NoRun): listed with what is known
        docs.append(doc)
    return docs
