"""Fairness of the world's inbox: no identity's messages may cost another's. `FairQueue` is
the queue between the zenoh callbacks (`command`, `token`, `enqueue`) and the world's main
thread (`get`, `taken`; world/inbox.py handles what it takes). Its items are typed
(world/inbox_messages.py).

Liveliness changes are coalesced per key (the main thread sees the latest state of each
token, however fast it flaps); every other message counts against its key (one agent's
command key, one query key), and past PER_KEY_MAX waiting on one key that key's new
messages are dropped and counted to it (`flooded_messages`), whatever the others send;
past INBOX_MAX waiting in all, any droppable message is. A well-formed command without
its owner's claim key (a rogue's) is counted in the callback and never queued, so that a
session flooding an agent's key with forged commands takes none of that agent's places.
"""

from __future__ import annotations

import queue
import threading
from typing import Any

from swarm.world.inbox_messages import Classifier, Command, Item, Query, Token
from swarm.world.state import RunState

INBOX_MAX = 100_000  # messages waiting for the main thread; commands and queries past it are dropped
PER_KEY_MAX = 256  # messages waiting on one key (a command every tick needs 1 to 2)


class FairQueue:
    """The world's inbox queue, shared by the zenoh callbacks and the main thread: messages
    waiting per key, the latest state of each liveliness token not yet handled, the
    messages dropped per key and the rogue commands counted per agent, under one lock.
    The items are world/inbox_messages.py's; `classifier` tells a command's (its checks
    read `state`, never change it)."""

    def __init__(self, state: RunState):
        self.state = state
        self.classifier = Classifier(state)
        self.queue: queue.SimpleQueue[Item] = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.waiting: dict[str, int] = {}
        self.alive: dict[str, Any] = {}
        self.flooded: dict[str, int] = {}
        self.noted: set[str] = set()  # keys whose drops have had their `limit` event
        self.rogue: dict[int, int] = {}  # agent -> commands without its owner's claim key, not yet counted
        self.dropped = 0  # messages dropped by the callbacks (see `_put`)

    # -- the zenoh callbacks' side --------------------------------------------------------------
    def command(self, key: str, payload: bytes) -> None:
        """A command sample on `key`: decoded once, here (a `Command`, or `Garbage` the main
        thread counts), and queued; a well-formed one without its owner's claim key (a
        rogue's, `Classifier.diverted`) is counted here and never queued, so that a rogue's
        flood never takes its owner's place in the inbox (the main thread only counts it:
        world/inbox.py, `note_dropped`)."""
        msg = self.classifier.decode(key, payload)
        if isinstance(msg, Command) and self.classifier.diverted(msg):
            with self.lock:
                self.rogue[msg.aid] = self.rogue.get(msg.aid, 0) + 1
            return
        self._put(key, msg, True)

    def token(self, key: str, kind: Any) -> None:
        """Liveliness token `key` changed to `kind`: it replaces the change of the same token
        still waiting (one `Token` queued per key at a time; never dropped)."""
        with self.lock:
            first = key not in self.alive
            self.alive[key] = kind
        if first:
            self.queue.put(Token(key))

    def enqueue(self, msg: Query, droppable: bool = True) -> None:
        """A query (`Join`, `Info`, `Admin`, `Supervise`), queued on its key; `droppable`
        False: never dropped (the launcher's reports)."""
        self._put(msg.key, msg, droppable)

    def _put(self, key: str, msg: Item, droppable: bool) -> None:
        """Queue `msg` on `key`; past PER_KEY_MAX waiting on its key, or INBOX_MAX in all, a
        droppable one is dropped and counted (see the module)."""
        with self.lock:
            n = self.waiting.get(key, 0)
            if droppable and (n >= PER_KEY_MAX or self.queue.qsize() >= INBOX_MAX):
                self.flooded[key] = self.flooded.get(key, 0) + 1
                self.dropped += 1
                return
            self.waiting[key] = n + 1
        self.queue.put(msg)

    # -- the main thread's side -----------------------------------------------------------------
    def get(self, timeout: float | None) -> Item | None:
        """The next message, waiting up to `timeout` s (None: for ever; 0 or less: not at
        all); None when none came."""
        try:
            return self.queue.get(timeout=timeout) if timeout is None or timeout > 0 else self.queue.get_nowait()
        except queue.Empty:
            return None

    def get_nowait(self) -> Item | None:
        try:
            return self.queue.get_nowait()
        except queue.Empty:
            return None

    def qsize(self) -> int:
        return self.queue.qsize()

    def latest_alive(self, key: str) -> Any:
        """The latest state of the token on `key` (its inbox entry is being handled)."""
        with self.lock:
            return self.alive.pop(key)

    def taken(self, item: Item) -> None:
        """The main thread took `item` off the inbox: one less waiting on its key."""
        if isinstance(item, Token):
            return
        key = item.key
        with self.lock:
            n = self.waiting.get(key, 0) - 1
            if n > 0:
                self.waiting[key] = n
            else:
                self.waiting.pop(key, None)

    def has_dropped(self) -> bool:
        """Messages dropped or rogue commands counted since `take_dropped` (read without the
        lock: a count that just came is seen at the next look)."""
        return bool(self.flooded or self.rogue)

    def take_dropped(self) -> tuple[dict[str, int], dict[int, int]]:
        """(messages dropped per key, rogue commands per agent) since the last call."""
        with self.lock:
            flooded, self.flooded = self.flooded, {}
            rogue, self.rogue = self.rogue, {}
        return flooded, rogue
