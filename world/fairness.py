"""Fairness of the world's inbox: no identity's messages may cost another's (a mixin of
`Inbox`, world/inbox.py; the zenoh callbacks call `enqueue`, the main thread `_taken`).

Liveliness changes are coalesced per key (the main thread sees the latest state of each
token, however fast it flaps); every other message counts against its key (one agent's
command key, one query key), and past PER_KEY_MAX waiting on one key that key's new
messages are dropped and counted to it (`flooded_messages`), whatever the others send;
past INBOX_MAX waiting in all, any droppable message is. A well-formed command without
its owner's claim key (a rogue's) is counted in the callback and never queued, so that a
session flooding an agent's key with forged commands takes none of that agent's places.
"""

from __future__ import annotations

import threading

from swarm.contracts import wire
from swarm.world.core import ACTIVE

INBOX_MAX = 100_000  # messages waiting for the main thread; commands and queries past it are dropped
PER_KEY_MAX = 256  # messages waiting on one key (a command every tick needs 1 to 2)
_FAIR_INIT = threading.Lock()


class _Fair:
    """What the zenoh callbacks and the main thread share: messages waiting per key, the
    latest state of each liveliness token not yet handled, drops per key."""

    def __init__(self):
        self.lock = threading.Lock()
        self.waiting: dict[str, int] = {}
        self.alive: dict[str, object] = {}
        self.flooded: dict[str, int] = {}
        self.noted: set[str] = set()  # keys whose drops have had their `limit` event
        self.rogue: dict[int, int] = {}  # agent -> commands without its owner's claim key, not yet counted


def _key_of(item) -> str:
    """The key a queued message counts against: its sample's key, or its query's."""
    if item[0] in ("cmd", "alive"):
        return item[1]
    try:
        return str(item[1].key_expr)
    except Exception:
        return item[0]


class Fairness:
    inbox_dropped = 0  # messages dropped by the callbacks (see `enqueue`)

    def _note_inbox_dropped(self) -> None:
        """Messages the zenoh callbacks dropped (see `enqueue`): counted to the agent whose
        key they came on, and one `limit` event per key the first time."""
        fair = self.fair
        with fair.lock:
            flooded, fair.flooded = fair.flooded, {}
            rogue, fair.rogue = fair.rogue, {}
        for aid, n in rogue.items():
            self.count_rogue(aid, n)
        if not flooded:
            return
        self.over_limit["inbox"] = self.inbox_dropped
        for key, n in flooded.items():
            try:
                aid = wire.agent_of_key(key)
            except wire.WireError:
                aid = None
            b = self.book.get(aid) if aid is not None else None
            if b is not None:
                b.flooded += n
            if key not in fair.noted:
                fair.noted.add(key)
                self.event(
                    "limit",
                    aid,
                    f"more than {PER_KEY_MAX} messages waiting on {key} (or {INBOX_MAX} in "
                    "all): its messages dropped, no one else's",
                    limit="inbox",
                    key=key,
                )

    @property
    def fair(self) -> _Fair:
        st = self.__dict__.get("_fair")
        if st is None:
            with _FAIR_INIT:
                st = self.__dict__.setdefault("_fair", _Fair())
        return st

    def enqueue(self, item, droppable: bool = True) -> None:
        """What a zenoh callback does with a message: queue it for the main thread. A
        liveliness change replaces the one of the same token still waiting (never dropped);
        past PER_KEY_MAX waiting on its key, or INBOX_MAX in all, a message is dropped and
        counted (see the module)."""
        fair = self.fair
        key = _key_of(item)
        if item[0] == "alive":
            with fair.lock:
                first = key not in fair.alive
                fair.alive[key] = item[2]
            if first:
                self.inbox.put(("alive", key))
            return
        if item[0] == "cmd":
            decoded = self._decoded(key, item[2])
            if decoded is not None and self._rogue(*decoded):
                return
            item = ("cmd", key, item[2], decoded)  # decoded once, here (world/inbox.py, _on_cmd)
        with fair.lock:
            n = fair.waiting.get(key, 0)
            if droppable and (n >= PER_KEY_MAX or self.inbox.qsize() >= INBOX_MAX):
                fair.flooded[key] = fair.flooded.get(key, 0) + 1
                self.inbox_dropped += 1
                return
            fair.waiting[key] = n + 1
        self.inbox.put(item)

    @staticmethod
    def _decoded(key: str, payload: bytes):
        """(agent id of the key, the command) when both decode and agree; None: garbage,
        which the main thread counts."""
        try:
            aid, cmd = wire.agent_of_key(key), wire.decode_cmd(payload)
        except wire.WireError:
            return None
        return (aid, cmd) if cmd.agent == aid else None

    def _rogue(self, aid: int, cmd) -> bool:
        """A well-formed command on an agent's key without the claim key of the process that
        owns the id (a rogue session's, or a stale process's): counted here and not queued,
        so that a rogue's flood never takes its owner's place in the inbox (the main thread
        only counts it: `_note_inbox_dropped`)."""
        b, core = self.book.get(aid), self.core
        if b is None or b.key is None or cmd.key == b.key:
            return False
        k = core.index.get(aid)
        if (
            (cmd.out is not None and (cmd.out == aid or cmd.out not in core.index))
            or k is None
            or core.state[k] != ACTIVE
            or cmd.tick > core.tick
        ):
            return False  # garbage or ignored, as the main thread says (world/inbox.py, _on_cmd)
        with self.fair.lock:
            self.fair.rogue[aid] = self.fair.rogue.get(aid, 0) + 1
        return True

    def _latest_alive(self, key: str):
        with self.fair.lock:
            return self.fair.alive.pop(key)

    def _taken(self, item) -> None:
        """The main thread took `item` off the inbox: one less waiting on its key."""
        if item[0] == "alive":
            return
        fair = self.fair
        key = _key_of(item)
        with fair.lock:
            n = fair.waiting.get(key, 0) - 1
            if n > 0:
                fair.waiting[key] = n
            else:
                fair.waiting.pop(key, None)
