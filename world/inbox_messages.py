"""The items of the world's inbox, typed, and `Classifier`: the one place that tells what a
command (or a liveliness key) is, for the zenoh callbacks and the main thread alike.

What goes through the queue (world/fairness.py, `FairQueue`), each handled by its type on
the main thread (world/inbox.py, `Inbox.handle`):

- `Command`: a well-formed command on its agent's command key, decoded once, in the callback;
- `Garbage`: a command that did not decode, or that is for another agent than its key's;
- `Token`: a liveliness token changed (coalesced per key: the main thread takes its latest
  state, `FairQueue.latest_alive`);
- `Join`, `Info`, `Admin`, `Supervise`: a query on that key (world/joins.py, world/inbox.py,
  world/reports.py answer them).

`Classifier.classify(key, payload)` turns a command sample into a `Command` or a rejection:
`Garbage` (malformed: counted to the world and to the agent whose key it came on), `Ignored`
(well-formed but of nobody's concern now: an agent not active, a tick not reached yet, a
duplicate or late one) or `Rogue` (without the claim key of the process that owns the id).
It is `decode` (the payload: state-free, done once, in the callback) then `admit` (the run's
state at that moment): the callback asks `diverted` (`admit`, short-cut for a command that
carries its owner's claim key) to divert a rogue's before it is queued (counted, never
queued: world/fairness.py); the main thread admits each command when it takes it
(world/inbox.py, `Inbox.handle`), against the state then. The checks are these, once.

Every type is a NamedTuple: `match` on the class, never on a tuple's length or a string tag;
two of different types never stand for each other (compare types, not tuples, in tests).
"""

from __future__ import annotations

from typing import Any, NamedTuple

from swarm.contracts import wire
from swarm.contracts.vocabulary import AgentState
from swarm.world.state import RunState

ACTIVE = AgentState.ACTIVE


# -- what the queue holds -----------------------------------------------------------------------
class Command(NamedTuple):
    """A well-formed command on agent `aid`'s command key `key` (the id of the key and of the
    command agree)."""

    key: str
    aid: int
    cmd: wire.Command


class Garbage(NamedTuple):
    """A malformed message on `key`: counted to the world and to agent `aid`, whose key it
    came on (None: no agent's). Queued (the main thread counts it) or a verdict of `admit`."""

    key: str
    aid: int | None


class Token(NamedTuple):
    """Agent liveliness token `key` changed; its latest state waits in the queue
    (`FairQueue.latest_alive`), however often it flapped meanwhile."""

    key: str


def _query_key(query: Any, fallback: str) -> str:
    """The key a query counts against (world/fairness.py): its own, or its kind's name."""
    try:
        return str(query.key_expr)
    except Exception:
        return fallback


class Join(NamedTuple):
    """A join query (world/joins.py)."""

    query: Any

    @property
    def key(self) -> str:
        return _query_key(self.query, "join")


class Info(NamedTuple):
    """A world/info query: the live view (world/inbox.py, `on_info`)."""

    query: Any

    @property
    def key(self) -> str:
        return _query_key(self.query, "info")


class Admin(NamedTuple):
    """A world/admin query: pause, resume, stop (world/inbox.py, `on_admin`)."""

    query: Any

    @property
    def key(self) -> str:
        return _query_key(self.query, "admin")


class Supervise(NamedTuple):
    """A world/supervise query: the launcher's reports (world/reports.py)."""

    query: Any

    @property
    def key(self) -> str:
        return _query_key(self.query, "supervise")


Query = Join | Info | Admin | Supervise
Item = Command | Garbage | Token | Query  # anything the queue holds


# -- verdicts on a command besides `Command` and `Garbage` ---------------------------------------
class Ignored(NamedTuple):
    """Well-formed, of nobody's concern now: counted (`ignored_messages`). `why`: "inactive"
    (no such agent active, or a tick not reached yet), "duplicate" (a tick its agent has
    commanded already) or "unknown" (a liveliness token of an agent the run lacks)."""

    aid: int | None
    why: str


class Rogue(NamedTuple):
    """A command on agent `aid`'s key without its owner's claim key (a rogue session's, or a
    stale process's). `claimed`: the id has an owner with a claim key; only such commands
    are diverted in the callback (world/fairness.py), the others are counted when handled."""

    aid: int
    claimed: bool


Rejection = Garbage | Ignored | Rogue
Verdict = Command | Rejection


class Classifier:
    """What a command sample (or a liveliness key) is, against the run's state (`state`, read
    only). Shared by the zenoh callbacks and the main thread: `cmd_keys` (an agent's own
    command key -> its id, the run's agents only, at most one key each) is filled by either
    and read without a lock (one key, one id, ever)."""

    def __init__(self, state: RunState):
        self.state = state
        self.cmd_keys: dict[str, int] = {}

    def classify(self, key: str, payload: bytes) -> Verdict:
        """The command sample (`key`, `payload`) as it stands now: `decode`, then `admit`."""
        msg = self.decode(key, payload)
        return self.admit(msg) if isinstance(msg, Command) else msg

    def decode(self, key: str, payload: bytes) -> Command | Garbage:
        """`Command` when the key's agent id and the payload both decode and agree; else
        `Garbage` (its `aid`: the key's id, when that much decoded). The id of an agent's
        own command key is parsed once (`cmd_keys`)."""
        aid = self.cmd_keys.get(key)
        try:
            if aid is None:
                aid = wire.agent_of_key(key)
                st = self.state
                if aid in st.engine.core.index and key == wire.agent_key(st.cfg.run, aid, "cmd"):
                    self.cmd_keys[key] = aid
            cmd = wire.decode_cmd(payload)
        except wire.WireError:
            return Garbage(key, aid)
        if cmd.agent != aid:  # a command for another agent than its key's
            return Garbage(key, aid)
        return Command(key, aid, cmd)

    def admit(self, msg: Command) -> Verdict:
        """`msg` itself when the run takes it now; else why not, in this order: `Garbage` (it
        follows itself or an agent the run lacks), `Ignored` (its agent is not active, or its
        tick not reached yet), `Rogue` (not its owner's claim key), `Ignored` (a tick its
        agent has commanded already: duplicate or late)."""
        key, aid, cmd = msg
        st = self.state
        core = st.engine.core
        out = cmd.out
        if out is not None and (out == aid or out not in core.index):
            return Garbage(key, aid)
        k = core.index.get(aid)
        if k is None or core.state[k] != ACTIVE or cmd.tick > core.tick:
            return Ignored(aid, "inactive")
        b = st.book.get(aid)
        if b is None:  # only seen from a callback: an added agent, its book not made yet
            return Ignored(aid, "inactive")
        if b.key is None or cmd.key != b.key:
            return Rogue(aid, b.key is not None)
        if cmd.tick <= b.last_cmd_tick:
            return Ignored(aid, "duplicate")
        return msg

    def diverted(self, msg: Command) -> bool:
        """For the callback: is `msg` a rogue's on an id whose owner has a claim key (`Rogue`,
        `claimed`: counted there, never queued)? A command carrying its owner's claim key is
        not, whatever else it is (`admit` tells the rest): that, the common case, is known
        at once, without the other checks."""
        b = self.state.book.get(msg.aid)
        if b is None or b.key is None or msg.cmd.key == b.key:
            return False
        verdict = self.admit(msg)
        return isinstance(verdict, Rogue) and verdict.claimed

    def token(self, key: str) -> int | Garbage | Ignored:
        """The agent id of liveliness key `key`, when the run has that agent; else `Garbage`
        (not an agent key) or `Ignored` (an agent the run lacks)."""
        try:
            aid = wire.agent_of_key(key)
        except wire.WireError:
            return Garbage(key, None)
        if aid not in self.state.engine.core.index:
            return Ignored(aid, "unknown")
        return aid
