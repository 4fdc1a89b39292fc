"""Fairness of the world's inbox: no identity's messages may cost another's. `FairQueue` is
the queue between the zenoh callbacks (`enqueue`) and the world's main thread (`get`,
`taken`; world/inbox.py handles what it takes).

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

from swarm.contracts import wire
from swarm.contracts.vocabulary import AgentState
from swarm.world.state import RunState

INBOX_MAX = 100_000  # messages waiting for the main thread; commands and queries past it are dropped
PER_KEY_MAX = 256  # messages waiting on one key (a command every tick needs 1 to 2)


def _key_of(item: tuple) -> str:
    """The key a queued message counts against: its sample's key, or its query's."""
    if item[0] in ("cmd", "alive"):
        return item[1]
    try:
        return str(item[1].key_expr)
    except Exception:
        return item[0]


class FairQueue:
    """The world's inbox queue, shared by the zenoh callbacks and the main thread: messages
    waiting per key, the latest state of each liveliness token not yet handled, the
    messages dropped per key and the rogue commands counted per agent, under one lock.
    `state` is read (not changed) by the callbacks to tell a rogue's command (`_rogue`)."""

    def __init__(self, state: RunState):
        self.state = state
        self.queue: queue.SimpleQueue[tuple] = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.waiting: dict[str, int] = {}
        self.alive: dict[str, Any] = {}
        self.flooded: dict[str, int] = {}
        self.noted: set[str] = set()  # keys whose drops have had their `limit` event
        self.rogue: dict[int, int] = {}  # agent -> commands without its owner's claim key, not yet counted
        self.dropped = 0  # messages dropped by the callbacks (see `enqueue`)
        # An agent's own command key -> its id, for the agents of the run (at most one key each:
        # `_decoded`); filled by the callbacks, read without the lock (one key, one id, ever).
        self.cmd_keys: dict[str, int] = {}

    # -- the zenoh callbacks' side --------------------------------------------------------------
    def enqueue(self, item: tuple, droppable: bool = True) -> None:
        """What a zenoh callback does with a message: queue it for the main thread. A
        liveliness change replaces the one of the same token still waiting (never dropped);
        past PER_KEY_MAX waiting on its key, or INBOX_MAX in all, a message is dropped and
        counted (see the module)."""
        key = _key_of(item)
        if item[0] == "alive":
            with self.lock:
                first = key not in self.alive
                self.alive[key] = item[2]
            if first:
                self.queue.put(("alive", key))
            return
        if item[0] == "cmd":
            decoded = self._decoded(key, item[2])
            if decoded is not None and self._rogue(*decoded):
                return
            item = ("cmd", key, item[2], decoded)  # decoded once, here (world/inbox.py, on_cmd)
        with self.lock:
            n = self.waiting.get(key, 0)
            if droppable and (n >= PER_KEY_MAX or self.queue.qsize() >= INBOX_MAX):
                self.flooded[key] = self.flooded.get(key, 0) + 1
                self.dropped += 1
                return
            self.waiting[key] = n + 1
        self.queue.put(item)

    def _decoded(self, key: str, payload: bytes) -> tuple[int, wire.Command] | None:
        """(agent id of the key, the command) when both decode and agree; None: garbage,
        which the main thread counts. The id of an agent's own command key is parsed once."""
        try:
            aid = self.cmd_keys.get(key)
            if aid is None:
                aid = wire.agent_of_key(key)
                if aid in self.state.core.index and key == wire.agent_key(self.state.cfg.run, aid, "cmd"):
                    self.cmd_keys[key] = aid
            cmd = wire.decode_cmd(payload)
        except wire.WireError:
            return None
        return (aid, cmd) if cmd.agent == aid else None

    def _rogue(self, aid: int, cmd: wire.Command) -> bool:
        """A well-formed command on an agent's key without the claim key of the process that
        owns the id (a rogue session's, or a stale process's): counted here and not queued,
        so that a rogue's flood never takes its owner's place in the inbox (the main thread
        only counts it: world/inbox.py, `note_dropped`)."""
        b, core = self.state.book.get(aid), self.state.core
        if b is None or b.key is None or cmd.key == b.key:
            return False
        k = core.index.get(aid)
        if (
            (cmd.out is not None and (cmd.out == aid or cmd.out not in core.index))
            or k is None
            or core.state[k] != AgentState.ACTIVE
            or cmd.tick > core.tick
        ):
            return False  # garbage or ignored, as the main thread says (world/inbox.py, on_cmd)
        with self.lock:
            self.rogue[aid] = self.rogue.get(aid, 0) + 1
        return True

    # -- the main thread's side -----------------------------------------------------------------
    def get(self, timeout: float | None) -> tuple | None:
        """The next message, waiting up to `timeout` s (None: for ever; 0 or less: not at
        all); None when none came."""
        try:
            return self.queue.get(timeout=timeout) if timeout is None or timeout > 0 else self.queue.get_nowait()
        except queue.Empty:
            return None

    def get_nowait(self) -> tuple | None:
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

    def taken(self, item: tuple) -> None:
        """The main thread took `item` off the inbox: one less waiting on its key."""
        kind = item[0]
        if kind == "alive":
            return
        key = item[1] if kind == "cmd" else _key_of(item)
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
