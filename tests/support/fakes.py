"""A fake zenoh session for the agent's and the world's logic (the dora `MockNode` idea):
publishers record what is put, subscribers and queryables keep their callbacks so a test
can feed them, queries return scripted replies. No network, milliseconds per test."""

from __future__ import annotations

from dataclasses import dataclass, field


class FakePublisher:
    def __init__(self, session: FakeSession, key: str):
        self.session, self.key = session, key

    def put(self, payload: bytes) -> None:
        self.session.sent.append((self.key, bytes(payload)))

    def undeclare(self) -> None:
        pass


@dataclass
class FakeQuery:
    """What a queryable's callback gets: a payload, parameters, and reply() that records."""

    payload_bytes: bytes | None = None
    parameters: str = ""
    replies: list = field(default_factory=list)
    key_expr: str = ""

    @property
    def payload(self):
        return None if self.payload_bytes is None else _Bytes(self.payload_bytes)

    dropped: bool = False

    def reply(self, key: str, payload: bytes) -> None:
        assert not self.dropped, "a reply to a query already finished"
        self.replies.append((key, bytes(payload)))

    def drop(self) -> None:
        """Finish the query (transport.answer does, right after its reply)."""
        self.dropped = True


class _Bytes:
    def __init__(self, b: bytes):
        self.b = b

    def to_bytes(self) -> bytes:
        return self.b


class _Declared:
    def __init__(self, kind: str, key: str, callback=None):
        self.kind, self.key, self.callback = kind, key, callback

    def undeclare(self) -> None:
        pass


class _Liveliness:
    def __init__(self, session: FakeSession):
        self.session = session

    def declare_token(self, key: str):
        self.session.tokens.append(key)
        return _Declared("token", key)

    def declare_subscriber(self, key: str, callback, history: bool = False):
        d = _Declared("liveliness_subscriber", key, callback)
        self.session.declared.append(d)
        return d

    def get(self, key: str, timeout: float = 1.0):
        """Scripted: the next entry of `session.token_replies` (how many tokens answer this
        query; for ever the last one when `session.tokens_stay`), none once it is empty.
        Noted in `session.token_gets` with the number of puts made before it."""
        ses = self.session
        ses.token_gets.append((key, len(ses.sent)))
        if not ses.token_replies:
            return []
        n = ses.token_replies[0] if ses.tokens_stay and len(ses.token_replies) == 1 else ses.token_replies.pop(0)
        return [_Reply()] * n


class _Reply:
    ok = object()  # a token that answered (zenoh: Reply.ok is its sample)


class _Info:
    def routers_zid(self):
        return []


class FakeSession:
    def __init__(self):
        self.sent: list[tuple[str, bytes]] = []  # (key, payload) of every put
        self.declared: list[_Declared] = []
        self.tokens: list[str] = []
        self.token_replies: list[int] = []  # liveliness queries: tokens answering each (_Liveliness.get)
        self.tokens_stay = False
        self.token_gets: list[tuple[str, int]] = []  # every liveliness query: (key, puts made before it)
        self.info = _Info()
        self.closed = False

    def declare_publisher(self, key: str, **_):
        return FakePublisher(self, key)

    def declare_subscriber(self, key: str, callback, **_):
        d = _Declared("subscriber", key, callback)
        self.declared.append(d)
        return d

    def declare_queryable(self, key: str, callback, **_):
        d = _Declared("queryable", key, callback)
        self.declared.append(d)
        return d

    def liveliness(self):
        return _Liveliness(self)

    def get(self, key: str, payload: bytes | None = None, timeout: float = 1.0):
        return []

    def put(self, key: str, payload: bytes) -> None:
        self.sent.append((key, bytes(payload)))

    def close(self) -> None:
        self.closed = True

    def on(self, key: str) -> list[bytes]:
        """Payloads put on `key`, in order."""
        return [p for k, p in self.sent if k == key]
