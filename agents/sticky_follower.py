"""One sticky follower's choice of the tick, with everything it keeps between ticks.

`StickyFollower.step` is the whole of it: whom to steer by (agents/sticky.Sticky),
where the out-neighbour must be while it coasts out of sight (agents/coast.Tracker), and
where to search while it has nobody (agents/search.SearchMemory). AgentBrain calls it on
every frame; the batch brains (agents/batch.py) call it for the followers whose tick is
not a plain keep, so both engines make the same choices with the same bits.
Pure: no I/O.
"""

from __future__ import annotations

from swarm.agents.coast import Tracker
from swarm.agents.search import SearchMemory
from swarm.agents.selection import Choice, cone, nearest, reach
from swarm.agents.sticky import LATE, LOST, SEARCH, Sticky
from swarm.contracts.brain_config import AgentConf, GainsConf, SensingConf
from swarm.contracts.frames import Contact
from swarm.contracts.observation import Search
from swarm.contracts.tuning_ticks import TuningTicks
from swarm.contracts.vocabulary import FollowState


class StickyFollower:
    """A follower under selection = "sticky" (see agents/sticky.Sticky)."""

    __slots__ = ("sticky", "tracker", "memory", "fresh", "state")

    def __init__(self, spec: AgentConf, gains: GainsConf, sensing: SensingConf, dt: float, max_hops: int):
        """spec/gains/sensing: the parts of its BrainConf (swarm/contracts/brain_config.py);
        dt (s); max_hops: the deepest a path can be."""
        sensing_range, fov = sensing.range, sensing.fov
        tune = TuningTicks.of(sensing.tuning, dt)
        self.sticky = Sticky(
            wait_ticks=max_hops,  # paths spread one hop per tick: the deepest is max_hops ticks away
            drain_ticks=max_hops,  # ... and so are the stale advertisements through it
            hold_ticks=tune.hold,
            coast_ticks=tune.coast,
            me=spec.id,
            reach=reach(sensing_range, tune.reach),
            cone=cone(fov, tune.reach),
        )
        self.tracker = Tracker(sensing_range, fov, spec.speed, tune.edge)
        self.memory = SearchMemory(sensing_range, spec.speed, gains.c2, spec.max_turn_rate, tune)
        self.fresh = True  # no frame yet
        # after each step: the machine's state, or SEARCH / LOST when it has nobody (flying a search or not)
        self.state = FollowState.ACQUIRE

    def step(
        self, contacts: tuple[Contact, ...], heading: float, time: float, last_u: float, tick: int = 0
    ) -> tuple[Choice, Search | None]:
        """This tick's choice, and the search circle to fly when it has nobody to steer by.
        tick: the frame's; a follower whose first frame is not the run's first joined late."""
        if self.fresh:
            self.fresh = False
            if tick > 0:
                self.sticky.late_join()
        tracker = self.tracker

        def coast(out: int) -> Contact | None:
            return tracker.predict(out, heading, time)

        choice = self.sticky.choose(contacts, coast, heading)
        c = choice.contact
        predicted = c is not None and c is tracker.predicted
        if c is None:
            tracker.forget()
        elif not predicted:
            tracker.sighted(c, heading, time)
        # nobody to steer by: search about the nearest agent it senses with a path to a leader
        seen = None if c is not None else nearest(tuple(k for k in contacts if k.hops >= 0))
        search = self.memory.update(c, seen, heading, time, last_u, predicted)
        state = self.sticky.state
        if c is None and state is not LATE:  # LOST, SEARCH: what it flies
            state = LOST if search is None else SEARCH
        self.state = state
        return choice, search
