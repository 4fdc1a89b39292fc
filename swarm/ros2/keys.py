"""rmw_zenoh's zenoh keys: a topic's data key and the liveliness tokens of nodes, publishers
and subscriptions (the ROS graph).

Data key: `<domain>/<topic without its leading and trailing slash>/<dds type>/<type hash>`, the
inner slashes kept. Tokens:
    @ros2_lv/<domain>/<zid>/<node_id>/<node_id>/NN/<enclave>/<namespace>/<node>
    @ros2_lv/<domain>/<zid>/<node_id>/<entity_id>/<MP|MS|SS|SC>/<enclave>/<namespace>/<node>
        /<topic>/<dds type>/<hash>/<qos>      (one key, no line break)
where every `/` inside a chunk is `%` (`mangle`) and an empty chunk is `%`; the topic is its
fully-qualified name. `@ros2_lv` is a hermetic chunk: only `@ros2_lv/<domain>/**` matches it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarm.ros2.types import BY_NAME, RosType

LIVELINESS = "@ros2_lv"
ENTITY_KINDS = ("MP", "MS", "SS", "SC")  # publisher, subscription, service server, service client
NODE_KIND = "NN"
DEFAULT_DEPTH = 42  # rmw_zenoh's default depth: the QoS text leaves it out


def mangle(name: str) -> str:
    """ "/robot1/cmd_vel" -> "%robot1%cmd_vel"; "" and "/" -> "%"."""
    return name.replace("/", "%") if name else "%"


def unmangle(chunk: str) -> str:
    return chunk.replace("%", "/")


def normalize_namespace(namespace: str) -> str:
    """A namespace as rcl writes it: "" and "/" -> "/", "tb3_0" and "/tb3_0/" -> "/tb3_0"."""
    return "/" + namespace.strip("/")


def resolve(namespace: str, topic: str) -> str:
    """The fully-qualified name of `topic` in `namespace`: absolute names stay, relative ones
    go under the namespace ("cmd_vel" in "/tb3_0" -> "/tb3_0/cmd_vel")."""
    if topic.startswith("/"):
        return topic
    ns = namespace.strip("/")
    return f"/{ns}/{topic}" if ns else f"/{topic}"


def topic_key(domain: int, topic: str, rtype: RosType, distro: str = "jazzy") -> str:
    """The data key of a fully-qualified `topic` ("/robot1/cmd_vel"; the leading slash may be left out)."""
    name = topic.removeprefix("/").removesuffix("/")
    return f"{domain}/{name}/{rtype.dds}/{rtype.hash_for(distro)}"


@dataclass(frozen=True)
class QoS:
    """The QoS a topic is declared with, as far as the robots need: reliability, durability and
    depth of a KEEP_LAST history (deadline, lifespan, liveliness stay rmw_zenoh's defaults)."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def encode(self) -> str:
        """rmw_zenoh's `qos_to_keyexpr`: `R:D:H,depth:DLs,DLns:LSs,LSns:LV,LVs,LVns`, each field
        empty where it equals rmw_zenoh's default (RELIABLE, VOLATILE, KEEP_LAST, depth 42,
        infinite durations, AUTOMATIC liveliness). QoS() -> "::,10:,:,:,,"."""
        rel = "" if self.reliable else "2"
        dur = "1" if self.transient_local else ""
        depth = "" if self.depth == DEFAULT_DEPTH else str(self.depth)
        return f"{rel}:{dur}:,{depth}:,:,:,,"

    @classmethod
    def decode(cls, text: str) -> QoS:
        """The reliability, durability and depth of a QoS text (ValueError if it is not one;
        a KEEP_ALL history reads as depth 0)."""
        fields = text.split(":")
        if len(fields) != 6 or [f.count(",") for f in fields[2:]] != [1, 1, 1, 2]:
            raise ValueError(f"not an rmw_zenoh QoS text: {text!r}")
        rel, dur = fields[0], fields[1]
        history, depth = fields[2].split(",")
        if rel not in ("", "0", "1", "2") or dur not in ("", "0", "1", "2") or history not in ("", "0", "1", "2"):
            raise ValueError(f"not an rmw_zenoh QoS text: {text!r}")
        if depth and not depth.isdigit():
            raise ValueError(f"not an rmw_zenoh QoS text: {text!r}")
        return cls(
            reliable=rel != "2",
            transient_local=dur == "1",
            depth=0 if history == "2" else int(depth) if depth else DEFAULT_DEPTH,
        )


DEFAULT_QOS = QoS()  # reliable, volatile, keep last 10: rclcpp's QoS(10), a TurtleBot3's cmd_vel and odom


def node_token(domain: int, zid: str, node_id: int, namespace: str, node: str, enclave: str = "") -> str:
    """The NN token of node `node` in `namespace` ("" or "/" for the root)."""
    return f"{LIVELINESS}/{domain}/{zid}/{node_id}/{node_id}/{NODE_KIND}/{mangle(enclave)}/{mangle(namespace)}/{node}"


def entity_token(
    domain: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    namespace: str,
    node: str,
    topic: str,
    rtype: RosType,
    qos: QoS,
    distro: str = "jazzy",
    enclave: str = "",
) -> str:
    """The token of a publisher (kind "MP") or subscription ("MS") of node `node` on `topic`
    (a relative topic is resolved in `namespace`)."""
    if kind not in ENTITY_KINDS:
        raise ValueError(f"entity kind {kind!r} is not one of {', '.join(ENTITY_KINDS)}")
    return (
        f"{LIVELINESS}/{domain}/{zid}/{node_id}/{entity_id}/{kind}/{mangle(enclave)}/{mangle(namespace)}/{node}/"
        f"{mangle(resolve(namespace, topic))}/{rtype.dds}/{rtype.hash_for(distro)}/{qos.encode()}"
    )


@dataclass(frozen=True)
class EntityInfo:
    """A parsed liveliness token. Names are unmangled: namespace "/" for the root (rcl's form),
    topic fully qualified ("/robot1/cmd_vel"). A node's own token (kind "NN") has empty topic,
    dds_type, type_hash and qos_text."""

    kind: str  # NN, MP, MS, SS, SC
    namespace: str
    node: str
    topic: str
    dds_type: str
    type_hash: str
    qos_text: str
    domain: int = 0
    zid: str = ""
    node_id: int = 0
    entity_id: int = 0
    enclave: str = "/"
    key: str = field(default="", compare=False)  # the whole token (its XXH3-128 is a publisher's GID)

    @property
    def rtype(self) -> RosType | None:
        """The RosType of the token's DDS type name, None for one swarm.ros2 does not know."""
        return BY_NAME.get(self.dds_type)

    @property
    def qos(self) -> QoS | None:
        try:
            return QoS.decode(self.qos_text)
        except ValueError:
            return None


def parse_entity_token(key: str) -> EntityInfo | None:
    """The node, publisher, subscription or service token `key`, or None when `key` is not one."""
    chunks = key.split("/")
    if len(chunks) < 9 or chunks[0] != LIVELINESS or any(not c for c in chunks):
        return None
    _, domain, zid, node_id, entity_id, kind, enclave, namespace, node = chunks[:9]
    if not all(c.isascii() and c.isdigit() for c in (domain, node_id, entity_id)):
        return None
    if kind == NODE_KIND and len(chunks) == 9:
        topic = dds_type = type_hash = qos_text = ""
    elif kind in ENTITY_KINDS and len(chunks) in (13, 14):  # rolling may append a 14th chunk (backends)
        topic, dds_type, type_hash, qos_text = unmangle(chunks[9]), unmangle(chunks[10]), chunks[11], chunks[12]
    else:
        return None
    return EntityInfo(
        kind=kind,
        namespace=unmangle(namespace),
        node=node,
        topic=topic,
        dds_type=dds_type,
        type_hash=type_hash,
        qos_text=qos_text,
        domain=int(domain),
        zid=zid,
        node_id=int(node_id),
        entity_id=int(entity_id),
        enclave=unmangle(enclave),
        key=key,
    )
