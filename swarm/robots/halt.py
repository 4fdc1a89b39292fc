"""Zero twists to every robot of a robots file, straight onto the robots' network, without the
world (docs/guides/robots.md#stops): what `swarm up` sends when its world exits
(swarm/robots/run_record.py `WorldExitStop`), what `swarm estop` sends (swarm/api/estop.py),
and what the guard sends to a robot whose commands stopped (swarm/robots/guard.py).

A `HaltPlan` says where: the robots' router and its credentials (the robots file's `[ros2]`),
and per robot its command topic and the command types to send (`Twist`, `TwistStamped`). For
`cmd_type = "auto"` the type is read, as the world's plant reads it, from the robot's own
subscription token on its command topic (`learn_types`); a robot whose type cannot be told
(no token, both types, another type) gets both: a stop never refuses, and a sample of a type
the robot does not subscribe to goes nowhere (the type is in the key). A plan is plain data
(`to_json` / `from_json`): `swarm up` writes the one of its run into the runtime dir
(`RunRecord`, swarm/robots/run_record.py, with `WorldExitStop`) with the types it learned,
so that `swarm estop` on that machine can stop the robots with the world stalled or gone,
without reading or validating the robots file again.

`Halt` opens a zenoh client session on the router and declares one publisher per robot and
type, on the keys the plant uses, every sample with rmw_zenoh's attachment (sequence number,
time, a GID of our own). It declares no publisher token: the world's graph watcher names any
publisher on a robot's command topic, and a stop that is only armed is no other publisher;
the samples themselves are seen (and named by their GID) when they are sent.
"""

from __future__ import annotations

import json
import secrets
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

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
