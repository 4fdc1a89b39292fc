"""Zero twists to every robot of a robots file, straight onto the robots' network, without the
world (docs/guides/robots.md#stops): what `swarm up` sends when its world exits (`WorldExitStop`),
what `swarm estop` sends (swarm/robots/estop.py), and what the guard sends to a robot whose
commands stopped (swarm/robots/guard.py).

A `HaltPlan` says where: the robots' router and its credentials (the robots file's `[ros2]`),
and per robot its command topic and the command types to send (`Twist`, `TwistStamped`). For
`cmd_type = "auto"` the type is read, as the world's plant reads it, from the robot's own
subscription token on its command topic (`learn_types`); a robot whose type cannot be told
(no token, both types, another type) gets both: a stop never refuses, and a sample of a type
the robot does not subscribe to goes nowhere (the type is in the key). A plan is plain data
(`to_json` / `from_json`): `swarm up` writes the one of its run into the runtime dir
(`RunRecord`) with the types it learned, so that `swarm estop` on that machine can stop the
robots with the world stalled or gone, without reading or validating the robots file again.

`Halt` opens a zenoh client session on the router and declares one publisher per robot and
type, on the keys the plant uses, every sample with rmw_zenoh's attachment (sequence number,
time, a GID of our own). It declares no publisher token: the world's graph watcher names any
publisher on a robot's command topic, and a stop that is only armed is no other publisher;
the samples themselves are seen (and named by their GID) when they are sent.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarm.contracts.runtime_dir import pid_alive, read_private, runtime_dir, write_private
from swarm.ros2 import cdr
from swarm.ros2.attachment import attachment
from swarm.ros2.keys import LIVELINESS, parse_entity_token, topic_key
from swarm.ros2.types import TWIST, TWIST_STAMPED, RosType

if TYPE_CHECKING:
    from swarm.robots.config import RobotsFile

STOP_REPEAT = 3  # zero twists per robot and type, as the world sends at its end
STOP_GAP = 0.02  # s between them
OPEN_TIMEOUT_MS = 2000  # the robots' router must answer within this to be stopped by us
LEARN_TIMEOUT = 0.5  # s for the router's answer to the liveliness query (the robots' tokens)
TYPES = {TWIST.short: TWIST, TWIST_STAMPED.short: TWIST_STAMPED}
# swarm.contracts.transport's client_config settings, written out: that module (with the run's
# credentials, wire and TLS modules) took most of `swarm estop`'s start-up on a loaded machine
# (tests/process/test_robots_stops.py checks that both give the same config)
LEASE_MS = 1000
TLS = "transport/link/tls"
RECORD_SUFFIX = ".robots"  # <runtime dir>/<run>.robots: a run's HaltPlan (RunRecord)


class HaltError(Exception):
    """The robots' router cannot be reached: no zero twist was sent."""


@dataclass(frozen=True)
class Target:
    """One robot: its agent, namespace, fully qualified command topic, and the types to send."""

    agent: int
    namespace: str
    topic: str
    types: tuple[str, ...]  # "Twist", "TwistStamped" (both: not known)

    def label(self) -> str:
        return f"robot {self.agent} ({self.namespace or '/'})"


@dataclass(frozen=True)
class HaltPlan:
    """Where the zero twists go: the robots' router (with the robots file's credentials) and
    every robot's command topic and types."""

    connect: str
    domain: int
    distro: str
    targets: tuple[Target, ...]
    user: str | None = None
    password_file: str | None = None
    root_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    @classmethod
    def from_robots(cls, robots: RobotsFile, connect: str | None = None) -> HaltPlan:
        """The plan of a robots file (loaded: its paths are absolute or relative to here);
        `connect` instead of its `[ros2] connect` (the guard, on the robots' machine)."""
        ros2 = robots.ros2
        targets = tuple(
            Target(
                r.agent,
                r.namespace,
                r.topic(r.cmd_topic),
                (TWIST.short, TWIST_STAMPED.short) if r.cmd_type == "auto" else (r.cmd_type,),
            )
            for r in robots.robots
        )

        def text(p: Path | None) -> str | None:
            return None if p is None else str(Path(p).resolve())

        return cls(
            connect or ros2.connect,
            ros2.domain,
            ros2.distro,
            targets,
            ros2.user,
            text(ros2.password_file),
            text(ros2.root_ca),
            text(ros2.tls_cert),
            text(ros2.tls_key),
        )

    def with_types(self, learned: dict[int, str]) -> HaltPlan:
        """The plan with the types learned (agent -> "Twist" | "TwistStamped") for its robots."""
        targets = tuple(
            Target(t.agent, t.namespace, t.topic, (learned[t.agent],)) if t.agent in learned else t
            for t in self.targets
        )
        return replace(self, targets=targets)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> HaltPlan:
        """A plan written by `to_json`; ValueError for anything else."""
        try:
            targets = tuple(
                Target(int(t["agent"]), str(t["namespace"]), str(t["topic"]), tuple(str(x) for x in t["types"]))
                for t in data["targets"]
            )
            plan = cls(
                str(data["connect"]),
                int(data["domain"]),
                str(data["distro"]),
                targets,
                *(None if data.get(k) is None else str(data[k]) for k in cls._PATHS),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"not a halt plan: {e!r}") from None
        if not targets or any(not t.types or set(t.types) - set(TYPES) for t in targets):
            raise ValueError("not a halt plan: a robot without a command type")
        return plan

    _PATHS = ("user", "password_file", "root_ca", "tls_cert", "tls_key")

    def zenoh_config(self) -> Any:
        """A zenoh client of the robots' router, with the robots file's credentials."""
        identity = None
        if self.user is not None:
            try:
                with open(self.password_file or "", encoding="utf-8") as f:
                    password = f.readline().rstrip("\r\n")
            except OSError as e:
                why = f"cannot read the password ([ros2] password_file): {e.strerror}"
                raise HaltError(f"{self.password_file}: {why}") from None
            identity = (self.user, password)
        tls: dict[str, Any] = {}
        if self.root_ca is not None:
            tls[f"{TLS}/root_ca_certificate"] = self.root_ca
        if self.tls_cert is not None:
            tls |= {
                f"{TLS}/connect_certificate": self.tls_cert,
                f"{TLS}/connect_private_key": self.tls_key,
                f"{TLS}/enable_mtls": True,
            }
        settings: dict[str, Any] = {
            "mode": "client",
            "connect/endpoints": [self.connect],
            "connect/timeout_ms": OPEN_TIMEOUT_MS,
            "scouting/multicast/enabled": False,
            "transport/link/tx/lease": LEASE_MS,
            "transport/shared_memory/enabled": False,
        }
        if identity is not None:
            settings["transport/auth/usrpwd"] = {"user": identity[0], "password": identity[1]}
        settings.update(tls)
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        cfg = zenoh.Config()
        for key, value in settings.items():
            cfg.insert_json5(key, json.dumps(value))
        return cfg


def type_of_subscriptions(topic: str, tokens: Iterable[tuple[str, str]]) -> str | None:
    """The command type of a robot from the (topic, DDS type) of the subscription tokens seen:
    "Twist" or "TwistStamped" when its topic's subscriptions take exactly one of them, None
    otherwise (none, both, or neither: the stop sends both). The plant's `cmd_type_from`
    refuses what this lets through: a stop must not refuse."""
    fits = {dds for t, dds in tokens if t == topic} & {TWIST.dds, TWIST_STAMPED.dds}
    if len(fits) != 1:
        return None
    return TWIST.short if fits == {TWIST.dds} else TWIST_STAMPED.short


def learn_types(session: Any, plan: HaltPlan, timeout: float = LEARN_TIMEOUT) -> dict[int, str]:
    """agent -> its command type, for the robots with more than one type in `plan`, from the
    subscription tokens on the router (one liveliness query); the robots it cannot tell left out."""
    unknown = [t for t in plan.targets if len(t.types) > 1]
    if not unknown:
        return {}
    subs: list[tuple[str, str]] = []
    try:
        for reply in session.liveliness().get(f"{LIVELINESS}/{plan.domain}/**", timeout=timeout):
            sample = reply.ok
            info = parse_entity_token(str(sample.key_expr)) if sample is not None else None
            if info is not None and info.kind == "MS":
                subs.append((info.topic, info.dds_type))
    except Exception:  # no answer: both types
        return {}
    found = {t.agent: type_of_subscriptions(t.topic, subs) for t in unknown}
    return {agent: kind for agent, kind in found.items() if kind is not None}


def zero_payload(kind: str) -> bytes:
    if kind == TWIST_STAMPED.short:
        return cdr.encode_twist_stamped(time.time_ns(), "", 0.0, 0.0)
    return cdr.encode_twist(0.0, 0.0)


class _Pub:
    """A publisher of one robot's commands of one type, rmw_zenoh's attachment on each sample."""

    def __init__(self, session: Any, plan: HaltPlan, target: Target, rtype: RosType, gid: bytes):
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        self.target, self.kind, self.gid = target, rtype.short, gid
        self.key = topic_key(plan.domain, target.topic, rtype, plan.distro)
        self.seq = 0
        self._pub = session.declare_publisher(
            self.key,
            reliability=zenoh.Reliability.RELIABLE,
            congestion_control=zenoh.CongestionControl.DROP,  # as rmw_zenoh: a stuck link must not block the others
            express=True,
        )

    def put(self, payload: bytes) -> None:
        self.seq += 1
        self._pub.put(payload, attachment=attachment(self.seq, time.time_ns(), self.gid))

    def undeclare(self) -> None:
        self._pub.undeclare()


class Halt:
    """A zenoh session on the robots' router, ready to zero-twist every robot of `plan`
    (`zero()`); `close()` ends it. `open_session(config)` opens it (tests pass their own).
    HaltError (one line) when the router cannot be reached."""

    def __init__(self, plan: HaltPlan, *, learn: bool = True, name: str = "swarm_halt", open_session=None):
        import zenoh  # lazy: as above

        self.plan = plan
        self.lock = threading.Lock()
        self.first_sent: float | None = None  # monotonic s when the first zero twists went out
        try:
            self.session = (open_session or zenoh.open)(plan.zenoh_config())
        except HaltError:
            raise
        except Exception as e:  # zenoh.ZError: nothing answers there (its text ends with a source path)
            why = str(e).split(" at /", 1)[0]
            raise HaltError(f"cannot reach the robots' zenoh router at {plan.connect}: {why}") from None
        try:
            if learn:
                self.plan = plan.with_types(learn_types(self.session, plan))
            self.gid = secrets.token_bytes(16)  # a GID of our own (no token: no XXH3 of one to match)
            self.pubs: list[_Pub] = [
                _Pub(self.session, self.plan, t, TYPES[kind], self.gid) for t in self.plan.targets for kind in t.types
            ]
        except BaseException:
            self.session.close()
            raise
        self.closed = False

    @property
    def robots(self) -> int:
        return len(self.plan.targets)

    def zero(self, repeat: int = STOP_REPEAT, gap: float = STOP_GAP, only: Sequence[int] | None = None) -> int:
        """Zero twists to every robot (or the agents `only`), `repeat` times `gap` s apart; how
        many robots they went to."""
        pubs = [p for p in self.pubs if only is None or p.target.agent in only]
        with self.lock:
            if self.closed:
                return 0
            for i in range(repeat):
                for p in pubs:
                    try:
                        p.put(zero_payload(p.kind))
                    except Exception:  # one robot's error must not keep the others going
                        pass
                if i == 0 and self.first_sent is None:
                    self.first_sent = time.monotonic()
                if i < repeat - 1:
                    time.sleep(gap)
        return len({p.target.agent for p in pubs})

    def close(self) -> None:
        with self.lock:
            if self.closed:
                return
            self.closed = True
            for p in self.pubs:
                try:
                    p.undeclare()
                except Exception:
                    pass
            try:
                self.session.close()
            except Exception:
                pass


def zero_twist(plan: HaltPlan, repeat: int = STOP_REPEAT, **kw: Any) -> int:
    """Open, zero-twist every robot of `plan` `repeat` times, close; how many robots."""
    halt = Halt(plan, **kw)
    try:
        return halt.zero(repeat)
    finally:
        halt.close()


# -- a run's record: its robots, for `swarm estop` on its machine -------------------------------------
@dataclass(frozen=True)
class RunRecord:
    """What `swarm up --robots` leaves in the runtime dir while it runs: its run, its own pid
    and its world's, the robots file, and the plan (types as learned)."""

    run: str
    launcher_pid: int
    world_pid: int | None
    robots_file: str
    plan: HaltPlan
    written: float = field(default_factory=time.time)

    def to_bytes(self) -> bytes:
        return (json.dumps({**asdict(self), "plan": self.plan.to_json()}, indent=1) + "\n").encode()

    @classmethod
    def from_bytes(cls, raw: bytes) -> RunRecord:
        try:
            data = json.loads(raw)
            return cls(
                str(data["run"]),
                int(data["launcher_pid"]),
                None if data.get("world_pid") is None else int(data["world_pid"]),
                str(data["robots_file"]),
                HaltPlan.from_json(data["plan"]),
                float(data.get("written", 0.0)),
            )
        except (KeyError, TypeError, ValueError, RecursionError) as e:
            raise ValueError(f"not a run's robots record: {e}") from None


def record_path(run: str) -> Path:
    return runtime_dir() / f"{run}{RECORD_SUFFIX}"


def write_record(record: RunRecord) -> Path:
    path = record_path(record.run)
    write_private(path, record.to_bytes())
    return path


def read_records() -> list[tuple[Path, RunRecord, bool]]:
    """The records in the runtime dir: (path, record, its swarm up still runs), newest first;
    unreadable ones left out."""
    out = []
    for p in runtime_dir().glob(f"*{RECORD_SUFFIX}"):
        try:
            rec = RunRecord.from_bytes(read_private(p))
        except Exception:
            continue
        out.append((p, rec, pid_alive(rec.launcher_pid)))
    return sorted(out, key=lambda x: -x[1].written)


def find_record(run: str | None) -> RunRecord:
    """The runtime dir's record of run `run`, or of the only run whose `swarm up` still runs,
    or (none runs) of the latest one; UsageError (one line) otherwise."""
    from swarm.contracts.errors import UsageError  # lazy: for the error's path only (the e-stop's start-up)

    records = read_records()
    if run is not None:
        for _p, rec, _alive in records:
            if rec.run == run:
                return rec
        raise UsageError(f"no robots of run {run} on this machine: give --robots FILE")
    alive = [rec for _p, rec, up in records if up]
    if len(alive) == 1:
        return alive[0]
    if not alive and records:
        return records[0][1]  # the latest run to drive robots here, ended: its robots all the same
    if not alive:
        raise UsageError("no run has driven robots on this machine (swarm up --robots records it): give --robots FILE")
    names = ", ".join(r.run for r in alive)
    raise UsageError(f"{len(alive)} runs drive robots ({names}): pick one with --run, or give --robots FILE")


# -- swarm up: a zero twist to every robot when the world exits -----------------------------------------
def exit_words(status: int | None) -> str:
    """How a process ended, in words: "killed by SIGKILL", "exit code 0"."""
    if status is None:
        return "its exit not known"
    if status < 0:
        try:
            return f"killed by {signal.Signals(-status).name}"
        except ValueError:
            return f"killed by signal {-status}"
    return f"exit code {status}"


class WorldExitStop:
    """`swarm up --robots`: as soon as its world process exits, for any reason, a zero twist to
    every robot (STOP_REPEAT times), then one line: "robots: zero twist sent to N robots (the
    world exited: killed by SIGKILL)". The session to the robots' router is opened when the
    world starts (`started`), so nothing is left to do at the exit but send; a thread waits for
    the exit (waitid without reaping: the launcher reaps the world). The run's record is in the
    runtime dir (`swarm estop`) from the world's start on, and stays after the run (the next
    run's replaces it); `join()` (the launcher, once the world has ended) waits for the line."""

    def __init__(
        self,
        robots: RobotsFile,
        robots_file: Path,
        run: str,
        say: Callable[[str], None],
        ran: Callable[[], bool] = lambda: True,
    ):
        self.plan = HaltPlan.from_robots(robots)
        self.robots_file = robots_file.resolve()
        self.run, self.say, self.ran = run, say, ran
        self.thread: threading.Thread | None = None
        self.record: Path | None = None
        self.sent: int | None = None
        self.done = threading.Event()

    def started(self, world_pid: int) -> None:
        self.write(world_pid, self.plan)  # at once: an estop from now on knows the robots
        self.thread = threading.Thread(target=self._watch, args=(world_pid,), name="robots-world-exit", daemon=True)
        self.thread.start()

    def write(self, world_pid: int | None, plan: HaltPlan) -> None:
        try:
            self.record = write_record(RunRecord(self.run, os.getpid(), world_pid, str(self.robots_file), plan))
        except OSError:
            self.record = None
            return
        for path, rec, up in read_records():  # the records of runs ended before: this one is the latest
            if not up and rec.run != self.run:
                try:
                    path.unlink()
                except OSError:
                    pass

    def _watch(self, pid: int) -> None:
        halt: Halt | None = None
        why: str | None = None
        try:
            try:
                halt = Halt(self.plan, name="swarm_up")
                self.write(pid, halt.plan)  # with the types learned
            except Exception as e:  # unreachable now: tried again at the exit
                why = str(e)
            status = _wait_exit(pid)
            if halt is None and not self.ran():  # the world could not start (e.g. no router): said by it
                return
            if halt is None:
                try:
                    halt = Halt(self.plan, name="swarm_up")
                except Exception as e:
                    if self.ran():
                        self.say(f"robots: NO zero twist sent (the world exited: {exit_words(status)}): {e or why}")
                    return
            self.sent = halt.zero()
            self.say(
                f"robots: zero twist sent to {self.sent} robots (the world exited: {exit_words(status)})"
                if self.sent != 1
                else f"robots: zero twist sent to 1 robot (the world exited: {exit_words(status)})"
            )
        finally:
            if halt is not None:
                halt.close()
            self.done.set()

    def join(self, timeout: float = 10.0) -> None:
        """Until the zero twists were sent and said (at most `timeout` s). The record stays: an
        estop after the run still finds its robots (the next run's record replaces it)."""
        if self.thread is not None:
            self.done.wait(timeout)


def _wait_exit(pid: int) -> int | None:
    """Block until child `pid` has exited, without reaping it; its status (negative: the
    signal), None when it is no child of ours any more (reaped meanwhile)."""
    while True:
        try:
            info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)
        except ChildProcessError:
            return None
        except InterruptedError:
            continue
        if info is None:
            continue
        return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status
