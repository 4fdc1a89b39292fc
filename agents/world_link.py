"""An agent's link to its world: there, gone, or only not answering for a while.

The world's liveliness token vanishing (a DELETE at the agent) means one of three things:

- only the agent's own link dropped (the agent was stalled: SIGSTOP, a starved CPU): the
  hub and the token are back within a moment; carry on;
- the world is gone (killed, or ended and the end notice was missed): its endpoint refuses
  connections; the agent exits 4, or with --wait-world waits for a new world;
- the world stopped answering (SIGSTOP, an overloaded host, a network cut): its endpoint
  still accepts connections, or does not answer at all; the agent waits up to `grace` s.
  When the token comes back through the same hub (the same zenoh id) the agent carries on
  as if nothing had happened (same brain, same claim); a different hub is a new world,
  joined afresh. After the grace the agent exits 5 (or waits on with --wait-world).

zenoh notices a silent world after the world's link lease (1 s), so the agent exits
about 1 s + grace after the world stopped. See docs/reference/protocol.md, section 6.5.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from swarm.agents.joining import AgentExit
from swarm.contracts import wire
from swarm.contracts.lifeline import endpoint_refuses
from swarm.contracts.vocabulary import ExitCode

log = logging.getLogger(__name__)

HERE, WAITING, GONE = "here", "waiting", "gone"  # what a DELETE turned out to be
RESUMED, NEW_WORLD, NOTHING = "resumed", "new world", "nothing"  # what a PUT means


class WorldLink:
    def __init__(
        self, session: Any, run: str, agent: int, endpoint: str | None, grace: float, wait_world: bool
    ) -> None:
        """grace: s to wait for a world that stopped answering (0: not at all); wait_world:
        wait for a new world instead of exiting when it is gone."""
        self.session = session
        self.run = run
        self.agent = agent
        self.endpoint = endpoint
        self.grace = grace
        self.wait_world = wait_world
        self.hub = self.hub_id()  # the world's hub (zenoh id) this agent joined through
        self.lost_at: float | None = None  # monotonic s: the world stopped answering (waiting)
        self.alive = True  # False: the world is gone (waiting for a new one with --wait-world)

    def hub_id(self) -> str | None:
        zids = [str(z) for z in self.session.info.routers_zid()]
        return zids[0] if zids else None

    def still_there(self, timeout: float) -> bool:
        """Wait up to `timeout` s for a link to the hub and the world's token on it."""
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if list(self.session.info.routers_zid()):
                left = max(0.1, t_end - time.monotonic())
                replies = self.session.liveliness().get(wire.world_alive_key(self.run), timeout=min(left, 0.5))
                if any(r.ok is not None for r in replies):
                    return True
            time.sleep(0.05)
        return False

    def on_delete(self, stalled: float) -> str:
        """The world's token vanished; `stalled`: s this process itself was not running just
        before. Returns HERE (still there) or WAITING (not answering: within the grace), or
        GONE with --wait-world; otherwise raises AgentExit(4) when it is gone."""
        if self.lost_at is not None or not self.alive:
            return WAITING if self.lost_at is not None else GONE
        # After our own stall, our link reconnects within ~0.5 s; a dead world is still
        # noticed within ~0.6 s.
        if self.still_there(3.0 if stalled else 0.6):
            log.info(
                "lost the world's token but the world is still there (stalled %.1f s before): carrying on", stalled
            )
            return HERE
        if self.grace > 0 and not (self.endpoint and endpoint_refuses(self.endpoint)):
            self.lost_at = time.monotonic()
            log.info(
                "the world of run %s stopped answering; waiting up to %g s for it (--world-grace)", self.run, self.grace
            )
            return WAITING
        self.alive = False
        if not self.wait_world:
            raise AgentExit(
                ExitCode.WORLD_GONE,
                f"agent {self.agent}: the world of run {self.run} vanished; exiting (use --wait-world to wait for it)",
            )
        log.info("the world vanished; waiting for it to come back")
        return GONE

    def on_put(self) -> str:
        """The world's token is there: RESUMED (the same hub answers again after a wait),
        NEW_WORLD (a different world, or one after the old one was gone) or NOTHING."""
        hub = self.hub_id()
        if self.lost_at is not None:
            waited, self.lost_at = self.waited(), None
            if hub is None or self.hub is None or hub == self.hub:
                log.info("the world answers again after %.1f s; carrying on", waited)
                return RESUMED
            self.hub = hub
            return NEW_WORLD
        if not self.alive:
            self.alive, self.hub = True, hub
            return NEW_WORLD
        return NOTHING

    def waited(self) -> float:
        return 0.0 if self.lost_at is None else time.monotonic() - self.lost_at

    def check(self) -> None:
        """Past the grace: exit 5, or with --wait-world count the world as gone (a new one may come)."""
        if self.lost_at is None or self.waited() <= self.grace:
            return
        if not self.wait_world:
            raise AgentExit(
                ExitCode.WORLD_SILENT,
                f"agent {self.agent}: the world of run {self.run} has not "
                f"answered for {self.grace:g} s (--world-grace); exiting",
            )
        self.lost_at, self.alive = None, False
        log.info("the world has not answered for %g s; waiting for a world", self.grace)
