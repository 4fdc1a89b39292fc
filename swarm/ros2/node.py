"""A ROS 2 node on a zenoh session, as rmw_zenoh has it: its liveliness token (NN), a token per
publisher (MP) and subscription (MS), data on `keys.topic_key`, and every sample with the 33-byte
attachment (sequence number from 1, source timestamp, the publisher's GID). `ros2 node list` and
`ros2 topic list` on the robots' side see what a Ros2Node declares; `remote_entities` reads what
the others declared.

A session that talks to rmw_zenoh's router (rmw_zenohd) must be a zenoh client: the router does
not forward between peers. Node and entity ids come from one counter per process (rmw_zenoh's
per-context counter): they only need to be unique per session.
"""

from __future__ import annotations

import itertools
import logging
import re
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from swarm.ros2.attachment import attachment, gid_for
from swarm.ros2.keys import (
    DEFAULT_QOS,
    LIVELINESS,
    EntityInfo,
    QoS,
    entity_token,
    node_token,
    normalize_namespace,
    parse_entity_token,
    resolve,
    topic_key,
)
from swarm.ros2.types import RosType

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

_ids = itertools.count()
_ids_lock = threading.Lock()
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # a node's name; a topic is such names between slashes


def _next_id() -> int:
    with _ids_lock:
        return next(_ids)


def _check_topic(topic: str) -> None:
    parts = topic.strip("/").split("/")
    if not all(NAME.fullmatch(p) for p in parts):
        raise ValueError(f"not a ROS topic name: {topic!r}")


class _Entity:
    def __init__(self, node: Ros2Node, kind: str, topic: str, rtype: RosType, qos: QoS) -> None:
        _check_topic(topic)
        self.node = node
        self.topic = resolve(node.namespace, topic)
        self.rtype = rtype
        self.qos = qos
        self.key = topic_key(node.domain, self.topic, rtype, node.distro)
        self.entity_id = _next_id()
        self.token_key = entity_token(
            node.domain,
            node.zid,
            node.node_id,
            self.entity_id,
            kind,
            node.namespace,
            node.name,
            self.topic,
            rtype,
            qos,
            node.distro,
        )
        self._token: Any = None
        self._closed = False

    def _declare_token(self) -> None:
        self._token = self.node.session.liveliness().declare_token(self.token_key)

    def _undeclare(self) -> None:  # the zenoh side of the entity (publisher, subscriber)
        pass

    def undeclare(self) -> None:
        """Undeclare the entity and its token (once; later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        self.node._forget(self)
        try:
            self._undeclare()
        finally:
            if self._token is not None:
                self._token.undeclare()


class Ros2Publisher(_Entity):
    """`put(payload)` sends CDR bytes on the topic with the next attachment."""

    def __init__(self, node: Ros2Node, topic: str, rtype: RosType, qos: QoS) -> None:
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        super().__init__(node, "MP", topic, rtype, qos)
        self.gid = gid_for(self.token_key)
        self.seq = 0  # the last sequence number sent (rmw_zenoh's first is 1)
        self._lock = threading.Lock()
        self._pub = node.session.declare_publisher(
            self.key,
            reliability=zenoh.Reliability.RELIABLE if qos.reliable else zenoh.Reliability.BEST_EFFORT,
            congestion_control=zenoh.CongestionControl.DROP,  # what rmw_zenoh does for KEEP_LAST
        )
        self._declare_token()

    @property
    def has_subscribers(self) -> bool:
        """Whether zenoh knows a subscription matching this publisher's key (its topic and type)."""
        status = self._pub.matching_status  # a MatchingStatus (its stub says bool): always truthy itself
        return bool(getattr(status, "matching", status))

    def put(self, payload: bytes) -> None:
        """Send `payload` (CDR bytes) with the attachment of the next sequence number."""
        with self._lock:
            if self._closed:
                raise RuntimeError(f"publisher on {self.topic} is undeclared")
            self.seq += 1
            self._pub.put(payload, attachment=attachment(self.seq, time.time_ns(), self.gid))

    def _undeclare(self) -> None:
        with self._lock:
            self._pub.undeclare()


def _attachment_of(sample: zenoh.Sample) -> bytes | None:
    att = sample.attachment
    return None if att is None else att.to_bytes()


class Ros2Subscriber(_Entity):
    """Calls `on_sample(payload)` for each sample of its topic and type, in zenoh's thread;
    `on_sample(payload, attachment)` with `with_attachment` (the attachment's bytes, None for a
    sample without: swarm/ros2/attachment.py parses them)."""

    def __init__(
        self,
        node: Ros2Node,
        topic: str,
        rtype: RosType,
        on_sample: Callable[..., None],
        qos: QoS,
        with_attachment: bool = False,
    ) -> None:
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        super().__init__(node, "MS", topic, rtype, qos)
        self.on_sample = on_sample
        put = zenoh.SampleKind.PUT

        def deliver(sample: zenoh.Sample) -> None:
            if sample.kind != put:
                return
            try:
                if with_attachment:
                    on_sample(sample.payload.to_bytes(), _attachment_of(sample))
                else:
                    on_sample(sample.payload.to_bytes())
            except Exception:  # zenoh's thread must go on: report and drop the sample
                log.exception("ROS 2 subscriber on %s: on_sample failed", self.topic)

        self._sub = node.session.declare_subscriber(self.key, deliver)
        self._declare_token()

    def _undeclare(self) -> None:
        self._sub.undeclare()


class Ros2Node:
    """A ROS node `name` in `namespace` ("" or "/" for the root) of ROS domain `domain`, speaking
    rmw_zenoh of `distro` (its type hashes) on `session`. It declares its NN token at once and
    `close()` undeclares everything it declared."""

    def __init__(
        self, session: zenoh.Session, name: str, namespace: str = "", domain: int = 0, distro: str = "jazzy"
    ) -> None:
        if not NAME.fullmatch(name):
            raise ValueError(f"not a ROS node name: {name!r}")
        if namespace.strip("/"):
            _check_topic(namespace)
        self.session = session
        self.name = name
        self.namespace = normalize_namespace(namespace)
        self.domain = domain
        self.distro = distro
        self.zid = str(session.info.zid())
        self.node_id = _next_id()
        self.token_key = node_token(domain, self.zid, self.node_id, self.namespace, name)
        self._entities: list[_Entity] = []
        self._others: list[Any] = []  # listeners and watchers: zenoh subscribers without a token
        self._lock = threading.Lock()
        self._closed = False
        self._token = session.liveliness().declare_token(self.token_key)

    def __enter__(self) -> Ros2Node:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"node {self.name} is closed")

    def _add(self, entity: _Entity) -> None:
        with self._lock:
            closed = self._closed
            if not closed:
                self._entities.append(entity)
        if closed:  # closed while the entity was being declared
            entity.undeclare()
            self._check_open()

    def _forget(self, entity: _Entity) -> None:
        with self._lock:
            if entity in self._entities:
                self._entities.remove(entity)

    def publisher(self, topic: str, rtype: RosType, qos: QoS = DEFAULT_QOS) -> Ros2Publisher:
        """A publisher of `rtype` on `topic` (relative names go under the node's namespace)."""
        self._check_open()
        pub = Ros2Publisher(self, topic, rtype, qos)
        self._add(pub)
        return pub

    def subscriber(
        self,
        topic: str,
        rtype: RosType,
        on_sample: Callable[..., None],
        qos: QoS = DEFAULT_QOS,
        *,
        with_attachment: bool = False,
    ) -> Ros2Subscriber:
        """A subscription to `rtype` on `topic`: `on_sample(cdr_bytes)` (with `with_attachment`:
        `on_sample(cdr_bytes, attachment_bytes_or_None)`) runs in zenoh's callback thread, for
        samples of this topic and type only (the type and its hash are in the key)."""
        self._check_open()
        sub = Ros2Subscriber(self, topic, rtype, on_sample, qos, with_attachment)
        self._add(sub)
        return sub

    def listen(self, topic: str, on_sample: Callable[[str, bytes, bytes | None], None]) -> Any:
        """Every sample on `topic`, of any type, without a subscription in the ROS graph (no
        token: `ros2 topic info` does not show it, a robot's `cmd_type = "auto"` does not read
        it): `on_sample(key, payload, attachment_or_None)` in zenoh's thread. What a watcher
        uses to see who else publishes on a topic; undeclared by `close()`."""
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        self._check_open()
        _check_topic(topic)
        name = resolve(self.namespace, topic).strip("/")
        put = zenoh.SampleKind.PUT

        def deliver(sample: zenoh.Sample) -> None:
            if sample.kind != put:
                return
            try:
                on_sample(str(sample.key_expr), sample.payload.to_bytes(), _attachment_of(sample))
            except Exception:  # zenoh's thread must go on
                log.exception("ROS 2 listener on %s: on_sample failed", topic)

        sub = self.session.declare_subscriber(f"{self.domain}/{name}/*/*", deliver)
        with self._lock:
            self._others.append(sub)
        return sub

    def watch(self, on_token: Callable[[str, EntityInfo, bool], None]) -> Any:
        """The ROS graph of this node's domain as it changes: `on_token(key, info, alive)` for
        every node, publisher, subscription or service token there is (history: the ones that
        exist already) and that comes (alive) or goes (not alive), ours excepted, in zenoh's
        thread. Undeclared by `close()`."""
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library

        self._check_open()
        put = zenoh.SampleKind.PUT

        def deliver(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            info = parse_entity_token(key)
            if info is None or key in self.own_tokens():
                return
            try:
                on_token(key, info, sample.kind == put)
            except Exception:  # zenoh's thread must go on
                log.exception("ROS 2 graph watcher: on_token failed")

        sub = self.session.liveliness().declare_subscriber(f"{LIVELINESS}/{self.domain}/**", deliver, history=True)
        with self._lock:
            self._others.append(sub)
        return sub

    def own_tokens(self) -> set[str]:
        with self._lock:
            return {self.token_key} | {e.token_key for e in self._entities}

    def remote_entities(
        self, topic: str | None = None, kind: str | None = None, timeout: float = 1.0
    ) -> list[EntityInfo]:
        """What the others in this node's domain have declared, as their liveliness tokens say
        (a liveliness get on `@ros2_lv/<domain>/**`, waiting at most `timeout` s for answers):
        nodes (kind "NN"), publishers ("MP"), subscriptions ("MS"), services. With `topic`
        (relative names go under the node's namespace), only the entities of that topic."""
        want_topic = resolve(self.namespace, topic) if topic is not None else None
        own = self.own_tokens()
        found: dict[str, EntityInfo] = {}
        for reply in self.session.liveliness().get(f"{LIVELINESS}/{self.domain}/**", timeout=timeout):
            sample = reply.ok
            if sample is None:  # an error reply carries no token
                continue
            key = str(sample.key_expr)
            info = parse_entity_token(key)
            if info is None or key in own or key in found:
                continue
            if (want_topic is None or info.topic == want_topic) and (kind is None or info.kind == kind):
                found[key] = info
        return list(found.values())

    def close(self) -> None:
        """Undeclare every publisher and subscription of the node, then its own token (once)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            entities = list(self._entities)
            others, self._others = self._others, []
        try:
            for other in others:
                try:
                    other.undeclare()
                except Exception:  # a closed session: nothing left to undeclare
                    pass
            for e in entities:
                e.undeclare()
        finally:
            self._token.undeclare()
