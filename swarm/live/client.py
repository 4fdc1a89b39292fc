"""Talking to a live run from any terminal: find it, query it, poke it. Everything goes
over zenoh (liveliness, queries, puts), never through files of the running processes,
so it works the same when the swarm runs on other machines.

Finding a run: every run has a credentials file (swarm/contracts/credentials.py) and the
CLI connects as the run's operator with it. With --credentials FILE (or
$SWARM_CREDENTIALS), that file's run; otherwise the local runs in the runtime dir
($SWARM_RUNTIME_DIR or /tmp/swarm-<uid>), those on --connect EP if given. With --run
ID, that run; otherwise the only one found. --run and --connect default to $SWARM_RUN and
$SWARM_CONNECT (swarm/cli/live.py), so a user with several runs can export one.
A local run on tcp/ or tls/ is dialled at its local door (a Unix socket of its hub in the
runtime dir: strangers at the network port do not hold it) unless --connect names an
endpoint. A session the hub did not let in is said as such, naming the endpoint
(`door_message`), never as a run not found (docs/guides/security.md#door).

Queries end as soon as what was asked for has answered (the world's one reply; every live
agent's status), never waiting for the query's timeout: a queryable's final answer can
come late (its process still holds the query), and only a world or an agent that does not
answer costs the timeout. A world that misses reads has ended only when its endpoint
refuses connections or it sent its end notice; one that failed several reads in a row over
several seconds without that has stopped answering (`Patience`): one timeout under load is
neither.
"""

from __future__ import annotations

import socket as so
import time
from collections.abc import Iterable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh

from swarm.contracts import credentials, wire
from swarm.contracts.credentials import Credentials
from swarm.contracts.errors import NoRunError, SwarmError, one_line
from swarm.contracts.identities import OPERATOR, CredentialsError
from swarm.contracts.lifeline import endpoint_refuses, endpoint_socket
from swarm.contracts.transport import (
    QUERY_TIMEOUT,
    dial_endpoint,
    local_door,
    open_client,
    query_statuses,
    runtime_dir,
    socket_path,
)
from swarm.contracts.wire import WireError

ENDED_FAILURES = 3  # failed reads in a row, ...
ENDED_SILENT_S = 5.0  # ... over at least this long, before a world that is still there has stopped answering


NoRun = NoRunError  # no (single) run matches, or its world stopped answering (swarm/contracts/errors.py)


@dataclass(frozen=True)
class RunRef:
    run: str
    endpoint: str
    creds: Credentials | None = None
    door: str | None = None  # the run's own local door, dialled instead of `endpoint` (transport.local_door)

    @property
    def dial(self) -> str:
        """The endpoint sessions to the run are opened on."""
        return self.door or self.endpoint


def _with_door(ref: RunRef) -> RunRef:
    """`ref` with the run's local door if its hub has one on this machine and it answers."""
    if socket_path(ref.endpoint) is not None:
        return ref
    door = local_door(ref.run)
    path = socket_path(door)
    answers = path is not None and path.exists() and _socket_answers(path)
    return RunRef(ref.run, ref.endpoint, ref.creds, door) if answers else ref


def _socket_answers(path) -> bool:
    s = so.socket(so.AF_UNIX, so.SOCK_STREAM)
    s.settimeout(0.2)
    try:
        s.connect(str(path))
        return True
    except OSError:
        return False
    finally:
        s.close()


# for a session to a listening hub (it takes ms; strangers at the door: docs/guides/security.md#door)
OPEN_TIMEOUT_S = 3.0


def _closes_at_once(endpoint: str, wait: float = 0.3) -> bool:
    """Whether the listener under `endpoint` closes a new connection before it says anything
    (zenoh does so when its places for connections in their handshake are all taken)."""
    made = endpoint_socket(endpoint, wait)
    if made is None:
        return False
    s, addr = made
    try:
        s.connect(addr)
        return s.recv(1) == b""
    except (ConnectionResetError, ConnectionAbortedError, BrokenPipeError):
        return True
    except OSError:  # no answer within `wait` (it waits for the handshake), or no connection at all
        return False
    finally:
        s.close()


def door_message(endpoint: str, waited: float) -> str:
    """One line on a session the hub at `endpoint` (which accepts connections) did not let in."""
    if _closes_at_once(endpoint):
        return f"the hub at {endpoint} refused the session (it closes new connections at once: too many waiting?)"
    return f"the hub at {endpoint} did not answer within {waited:g} s (or refused these credentials)"


def _listens(endpoint: str, tls_too: bool = False) -> bool:
    """Whether something accepts connections on `endpoint`. A tls/ one is taken to (unless
    `tls_too`): a connection that leaves before its TLS handshake stalls zenoh's TLS
    listener for 100 ms (eclipse-zenoh/zenoh#2685), so it is only probed once a session failed."""
    path = socket_path(endpoint)
    if path is not None:
        return _socket_answers(path)
    if endpoint.startswith("tls/") and not tls_too:
        return True
    return not endpoint_refuses(endpoint, timeout=0.3)


def _probe(ref: RunRef, timeout: float = 0.5, open_timeout: float = OPEN_TIMEOUT_S):
    """(a session to the world of `ref` if it is alive on its endpoint and lets these
    credentials in, else None; why not, in one line, when its hub listens but did not let
    the session in, else None)."""
    if not _listens(ref.dial):
        return None, None
    try:
        ses = open_client(ref.dial, timeout_ms=int(open_timeout * 1000), creds=ref.creds, door=False)
    except Exception:
        return None, door_message(ref.dial, open_timeout) if _listens(ref.dial, tls_too=True) else None
    try:
        replies = ses.liveliness().get(wire.world_alive_key(ref.run), timeout=timeout)
        if any(r.ok is not None for r in replies):
            return ses, None
    except Exception:
        pass
    ses.close()
    return None, None


def world_answers(ref: RunRef, timeout: float = 0.5) -> bool:
    """Whether the world of `ref` is alive on its endpoint (and lets these credentials in)."""
    ses, _ = _probe(ref, timeout)
    if ses is not None:
        ses.close()
    return ses is not None


def candidates(connect: str | None = None, creds_file: Path | None = None) -> list[RunRef]:
    """The runs these options point at, before asking any world: a credentials file's run,
    or the local runs (on `connect` only, if given)."""
    given = credentials.read(creds_file) if creds_file is not None else credentials.from_environment()
    if given is not None:
        given.identity(OPERATOR)  # a file of one agent's cannot run the live commands
        ref = RunRef(given.run, connect or given.endpoint, given)
        return [ref if connect else _with_door(ref)]
    dial = None if connect is None else dial_endpoint(connect)
    return [
        RunRef(c.run, c.endpoint, c) if dial else _with_door(RunRef(c.run, c.endpoint, c))
        for c in credentials.local_runs()
        if dial is None or c.endpoint == dial
    ]


def _candidates(connect: str | None, creds_file: Path | None, run: str | None) -> list[RunRef]:
    try:
        refs = candidates(connect, creds_file)
    except CredentialsError as e:
        raise NoRun(str(e)) from None
    return [r for r in refs if run is None or r.run == run]


def find_runs(connect: str | None = None, creds_file: Path | None = None, run: str | None = None) -> list[RunRef]:
    """The runs these options point at whose world answers (only run `run`, if given)."""
    return [r for r in _candidates(connect, creds_file, run) if world_answers(r)]


def where_looked(connect: str | None = None, creds_file: Path | None = None) -> str:
    if creds_file is not None:
        return str(creds_file)
    env = credentials.from_environment_path()
    if env is not None:
        return f"{env} ($SWARM_CREDENTIALS)"
    return f"local runs in {runtime_dir()}" + (f" on {connect}" if connect else "")


def open_run_session(connect: str | None = None, run: str | None = None, creds_file: Path | None = None) -> LiveRun:
    """A LiveRun, open, on the run a command should talk to (the session that found its world
    alive, so it is opened once), or NoRun with a one-line reason."""
    if run is not None:
        try:
            wire.check_run_id(run)
        except wire.WireError as e:
            raise NoRun(str(e)) from None
    where = where_looked(connect, creds_file)
    found, refused = [], []
    for ref in _candidates(connect, creds_file, run):
        ses, why = _probe(ref)
        if ses is not None:
            found.append((ref, ses))
        elif why is not None:
            refused.append(f"run {ref.run}: {why}")
    for _, ses in found[1:] if len(found) == 1 else found:
        ses.close()
    if not found and refused:
        raise NoRun("; ".join(refused))
    if not found:
        what = f"run {run!r}" if run else "no swarm is running"
        raise NoRun(
            f"{what} not found: looked at {where}"
            if run
            else f"{what}: looked at {where} "
            "(start one with `swarm up SCENARIO`; for a run on another machine pass "
            "--credentials FILE from `swarm credentials`)"
        )
    if len(found) > 1:
        raise NoRun(
            f"{len(found)} runs found ({', '.join(f'{r.run} on {r.endpoint}' for r, _ in found)}); "
            "pick one with --run (or export SWARM_RUN=ID)"
        )
    return LiveRun(*found[0])


def _first_reply(replies):
    """The first successful reply of a get (consolidation NONE: delivered as it arrives), or None."""
    for r in replies:
        if r.ok is not None:
            return r.ok
    return None


class LiveRun:
    """An open session to one run: `with LiveRun(ref) as live: live.info()` (`session`: one
    already open to it, which it then owns)."""

    def __init__(self, ref: RunRef, session=None):
        self.ref = ref
        self.session = session
        self.end_notice = False  # the world said the run ended (once `watch_end()` listens)
        self._end_sub = None

    def __enter__(self) -> LiveRun:
        if self.session is not None:
            return self
        try:
            self.session = open_client(
                self.ref.dial, timeout_ms=int(OPEN_TIMEOUT_S * 1000), creds=self.ref.creds, door=False
            )
        except Exception:
            if not _listens(self.ref.dial, tls_too=True):
                raise NoRun(f"nothing listens on {self.ref.dial} (the run {self.ref.run} has ended?)") from None
            raise NoRun(door_message(self.ref.dial, OPEN_TIMEOUT_S)) from None
        return self

    def __exit__(self, *exc) -> None:
        if self.session is not None:
            session, self.session = self.session, None
            session.close()

    def _get(self, selector: str, payload: bytes | None = None):
        """A get whose replies come as they arrive (not held back until the query ends)."""
        return self.session.get(
            selector, payload=payload, timeout=QUERY_TIMEOUT, consolidation=zenoh.ConsolidationMode.NONE
        )

    def _get_one(self, selector: str, decode, payload: bytes | None = None) -> dict:
        ok = _first_reply(self._get(selector, payload))  # the world's reply ends it, not the timeout
        if ok is None:
            raise NoRun(f"the world of run {self.ref.run} did not answer (it may have ended)")
        return decode(ok.payload.to_bytes())

    def world_alive(self) -> bool:
        replies = self.session.liveliness().get(wire.world_alive_key(self.ref.run), timeout=0.5)
        return any(r.ok is not None for r in replies)

    def info(self, sensing: bool = False) -> dict:
        """The world's view: tick, clock, paused, and per agent pose, state, out, errors..."""
        sel = wire.world_info_key(self.ref.run) + ("?sensing=1" if sensing else "")
        return self._get_one(sel, wire.decode_info)

    def statuses(self, expected: Iterable[int] | None = None) -> dict[int, dict]:
        """Each live agent's own status (its chosen out-neighbour, hops, phase, pid...), from
        one query to every agent's status queryable (malformed replies skipped). It ends once
        every agent of `expected` (e.g. the live ones of the world's info) has answered, or
        at the query's timeout (an agent that does not answer; `expected` None: always)."""
        return query_statuses(self.session, self.ref.run, QUERY_TIMEOUT, expected)

    def admin(self, cmd: str, by: str = "swarm cli") -> dict:
        rep = self._get_one(wire.world_admin_key(self.ref.run), wire.decode_admin_reply, wire.encode_admin(cmd, by=by))
        if not rep.get("ok"):
            raise NoRun(str(rep.get("error")))
        return rep

    def signal_agent(self, agent_id: int, signal_name: str) -> None:
        """Ask agent `agent_id` over zenoh to take a signal (KILL, TERM or STOP)."""
        self.session.put(wire.agent_key(self.ref.run, agent_id, "ctl"), wire.encode_ctl(signal_name))

    def watch_end(self) -> None:
        """From now on, note the world's end notice (`end_notice`)."""
        if self._end_sub is None:

            def on_control(sample) -> None:
                try:
                    if isinstance(wire.decode_control(sample.payload.to_bytes()), int):
                        self.end_notice = True
                except wire.WireError:
                    pass

            self._end_sub = self.session.declare_subscriber(wire.world_control_key(self.ref.run), on_control)

    def gone(self) -> bool:
        """Whether the world has ended for sure: it sent its end notice, or its endpoint
        refuses connections (a loaded or stalled world still accepts them)."""
        return self.end_notice or endpoint_refuses(self.ref.endpoint, timeout=0.3)


class Patience:
    """When a world that failed a read is over for a watcher (`swarm graph --watch`, `swarm
    watch`): at once when it is gone (`LiveRun.gone`: it ended), otherwise after
    ENDED_FAILURES failed reads in a row over at least ENDED_SILENT_S s (it stopped
    answering: `silent` is then True). A loaded world that misses a query, or a stalled one
    whose link dropped for a moment, is read again."""

    def __init__(self, live: LiveRun):
        self.live = live
        self.failures = 0
        self.since: float | None = None  # monotonic s of the first failure in a row
        self.silent = False  # over because the world stopped answering, not because it ended
        live.watch_end()

    def answered(self) -> None:
        self.failures, self.since, self.silent = 0, None, False

    def ended(self) -> bool:
        """After a failed read: True when the world has ended or stopped answering (`silent`)."""
        now = time.monotonic()
        self.failures += 1
        self.since = now if self.since is None else self.since
        self.silent = False
        if self.live.gone():
            return True
        self.silent = self.failures >= ENDED_FAILURES and now - self.since >= ENDED_SILENT_S
        return self.silent


@contextmanager
def talking():
    """Errors of the layers below while talking to a run (zenoh's, malformed replies,
    credentials) as a NoRunError of one line."""
    try:
        yield
    except SwarmError:
        raise
    except (WireError, CredentialsError) as e:
        raise NoRunError(one_line(e)) from None
    except Exception as e:  # zenoh's: a clear line, never a traceback
        raise NoRunError(f"cannot talk to the run: {one_line(e)}") from None
