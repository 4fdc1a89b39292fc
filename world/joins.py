"""Joining a run: what the world does with a join query, and the limits on claims.

A claim of an agent id is admitted by the roster (world/roster.py: the id's owner and its
claim key), and the reply carries the agent's configuration; an id the scenario does not
have joins as a new agent (`swarm spawn`) with the spec it sends, if the run may still
add one and the id is in the range the hub's access rules were made for. Claims are
limited per agent id by a token bucket, so one agent's flood does not use up another's.
zenoh callbacks only enqueue; these run on the world's main thread. A part of the world
process (world/process.py), with the run's state (world/state.py) in its constructor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from swarm.contracts import wire
from swarm.contracts.brain_config import BrainConf, LawConf
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import EventKind
from swarm.world.roster import AgentBook, admit, new_agent_spec
from swarm.world.state import RunState

# Join claims are limited per agent id (the hub lets agent k claim on its own key only, so
# one agent cannot use up another's): a burst, then a claim per s. Keys of ids the run
# cannot have (only an open hub lets those through) share one bucket.
JOIN_BURST, JOIN_RATE = 5, 1.0
STRANGER_BURST, STRANGER_RATE = 40, 20.0


class TokenBucket:
    """At most `rate` per s on average, and `burst` at once."""

    def __init__(self, rate: float, burst: float):
        self.rate, self.burst, self.level = rate, burst, burst
        self.at: float | None = None

    def take(self, now: float) -> bool:
        if self.at is not None:
            self.level = min(self.burst, self.level + (now - self.at) * self.rate)
        self.at = now
        if self.level < 1.0:
            return False
        self.level -= 1.0
        return True


class Joins:
    """Join queries and new agents. `add_sense(aid)`: the world's, declares the publisher of
    a new agent's frames (world/process.py)."""

    def __init__(self, state: RunState, add_sense: Callable[[int], None]):
        self.state = state
        self.add_sense = add_sense
        self.buckets: dict[int | None, TokenBucket] = {}  # join claims per agent id

    def _join_allowed(self, key: str) -> bool:
        st = self.state
        kid: int | None
        try:
            kid = wire.agent_of_key(key)
        except wire.WireError:
            kid = None
        if kid is None or (kid not in st.book and kid not in st.cfg.scenario.added_id_range):
            kid = None
        if kid not in self.buckets:
            self.buckets[kid] = (
                TokenBucket(JOIN_RATE, JOIN_BURST) if kid is not None else TokenBucket(STRANGER_RATE, STRANGER_BURST)
            )
        return self.buckets[kid].take(time.monotonic())

    def on_join(self, query: Any) -> None:
        st = self.state
        if not self._join_allowed(str(query.key_expr)):
            st.limited(
                "join_rate",
                f"join claims faster than {JOIN_BURST} at once and {JOIN_RATE:g} per s "
                "on one agent's key: claim refused",
            )
            answer(query, str(query.key_expr), wire.encode_join_reply(False, error="too many join claims; retry later"))
            return
        core = st.core
        try:
            req = wire.decode_join_request(query.payload.to_bytes() if query.payload else b"")
            aid = req["id"]
            if wire.agent_of_key(str(query.key_expr)) != aid:
                raise wire.WireError(f"a claim of agent {aid} on another agent's join key")
            if aid not in core.index:
                if req.get("spec") is None:
                    raise wire.WireError(
                        f"agent {aid} is not in scenario {st.cfg.scenario.name!r} "
                        f"(ids: {', '.join(map(str, core.scenario.ids))}); "
                        "a new agent needs a spec (swarm spawn --role --x --y ...)"
                    )
                self._check_addable(aid)
                self.add_agent(aid, req["spec"])
            key = admit(core, st.book[aid], req, time.monotonic())
            x, y, h = core.pose(aid)
            conf = BrainConf.from_scenario(core.scenario, aid)
            reply = wire.encode_join_reply(
                True,
                run=st.cfg.run,
                agent=aid,
                tick=core.tick,
                key=key,
                clock=st.cfg.clock,
                pose=[x, y, h],
                brain=conf.to_json(),
                own_laws=conf.law != LawConf(),
            )
        except wire.WireError as e:
            reply = wire.encode_join_reply(False, error=str(e))
        answer(query, str(query.key_expr), reply)

    def _check_addable(self, aid: int) -> None:
        """A new agent takes an id of the range the hub's access rules were made for, and
        only as many join the run as the scenario allows (run.max_added_agents)."""
        st = self.state
        s = st.cfg.scenario
        if len(st.book) - len(s.ids) >= s.added_agents_cap:
            st.limited(
                "added_agents", f"{s.added_agents_cap} agents added already (run.max_added_agents): agent {aid} refused"
            )
            raise wire.WireError(
                f"agent {aid}: this run has added {s.added_agents_cap} agents already, its limit (run.max_added_agents)"
            )
        ids = s.added_id_range
        if aid not in ids:
            raise wire.WireError(f"agent {aid}: agents added to this run take ids {ids.start}..{ids.stop - 1}")

    def add_agent(self, aid: int, spec: dict) -> None:
        """A new agent joins the run with its own spec (`swarm spawn`); raises WireError."""
        st = self.state
        a = new_agent_spec(aid, spec, st.core)
        st.engine.add_agent(a)
        st.book[aid] = AgentBook()
        self.add_sense(aid)
        st.event(EventKind.ADD, aid, f"new {a.role} at ({a.x:g}, {a.y:g}) m, {a.speed:g} m/s")
