"""Keeping an out-neighbour that has just left the sensor's reach: its predicted contact.

With a sensing range, a follower and the agent it follows can drift apart for a few
seconds at a time while they settle (a slow follower outside a fast leader's orbit is
lapped, and every lap takes the leader out of range for a while). Re-choosing on each
such gap restarts the follower's transient every few seconds, and it may never settle.
So a committed follower whose out-neighbour leaves the sensor's reach *at its edge* (its
last sighting was at `edge` x the range or more, or off its own heading by `edge` x half the
field of view or more; SelectionTuning.edge, 0.8) keeps it for up to SelectionTuning.coast_s
seconds (5), steering by where it predicts it. It advertises no path meanwhile (it cannot see
whether there still is one): its own followers hold it for as long (agents/sticky.Sticky). The prediction:

- from its last two sightings, the out-neighbour's speed (its displacement, with the
  follower's own dead-reckoned displacement taken out) and turn rate (the change of its
  sensed heading);
- flown forward as a unicycle with both held, while the follower's own motion is taken
  out by dead reckoning (agents/search.drift).

An out-neighbour that vanishes from the middle of the sensor's reach has dropped out: no
coasting, the follower reacts on that tick; and coasting ends as soon as the prediction
falls back inside the sensor's sure reach (short of the edge) without the agent being
sensed there: the prediction is wrong. Pure: no I/O; scalar `math` only, so the
batch brains call the same code per coasting follower and get the same bits.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from swarm.agents.search import anchor_point, drift
from swarm.contracts.frames import Contact
from swarm.contracts.orbits import wrap
from swarm.contracts.tuning_ticks import DEFAULT as DEFAULT_TUNING

_new = tuple.__new__
DEFAULT = DEFAULT_TUNING  # the edge, when not given


class Sighting(NamedTuple):
    id: int
    time: float  # s
    range: float  # m
    bearing: float  # rad, world frame
    heading: float  # its heading (rad)
    hops: int  # what it advertised
    own: float  # the follower's own heading then (rad)


class Tracker:
    """The last two sightings of the agent a follower steers by, and its prediction while
    it coasts (module docstring); one per brain."""

    __slots__ = ("edge_range", "edge_angle", "speed", "last", "prev", "state", "predicted")

    def __init__(self, sensing_range: float | None, fov: float | None, speed: float, edge: float = DEFAULT.edge):
        """edge: SelectionTuning.edge, the fraction of the range and half field of view
        beyond which a sighting is at the edge."""
        self.edge_range = math.inf if sensing_range is None else edge * sensing_range
        self.edge_angle = math.inf if fov is None or fov >= 2 * math.pi else edge * 0.5 * fov
        self.speed = speed
        self.last: Sighting | None = None
        self.prev: Sighting | None = None
        self.state: tuple | None = None  # while coasting: (x, y, heading, v, w, own heading, time)
        self.predicted: Contact | None = None  # the last contact `predict` returned

    def sighted(self, c: Contact, heading: float, time: float) -> None:
        """It sensed `c`, the agent it steers by, this tick."""
        last = self.last
        self.prev = last if last is not None and last.id == c.id else None
        # tuple.__new__ straight away: a third of the cost of Sighting(...), on every tick it keeps
        self.last = _new(Sighting, (c.id, time, c.range, c.bearing, c.heading, c.hops, heading))
        self.state = self.predicted = None

    def forget(self) -> None:
        self.last = self.prev = None
        self.state = self.predicted = None

    def _outside(self, rng: float, bearing: float, own: float) -> bool:
        """Is a point at (rng, bearing) from a follower heading `own` at the edge of its
        sensor's reach or beyond (where the sensor may miss it)?"""
        return rng >= self.edge_range or abs(wrap(bearing - own)) >= self.edge_angle

    def at_edge(self) -> bool:
        """Was the last sighting at the edge of the sensor's reach?"""
        s = self.last
        return s is not None and self._outside(s.range, s.bearing, s.own)

    def predict(self, out: int, heading: float, time: float) -> Contact | None:
        """The predicted contact of `out` at this tick (own heading, time), or None when it
        cannot coast: not the agent last sighted, one sighting only, or not at the edge."""
        if self.state is None:
            a, b = self.prev, self.last
            if a is None or b is None or b.id != out or not self.at_edge() or b.time <= a.time:
                return None
            span = b.time - a.time
            x1, y1 = anchor_point(a.range, a.bearing)
            x2, y2 = anchor_point(b.range, b.bearing)
            ox, oy = drift(0.0, 0.0, a.own, b.own, self.speed, span)  # minus own displacement
            v = math.hypot(x2 - x1 - ox, y2 - y1 - oy) / span
            w = wrap(b.heading - a.heading) / span
            self.state = (x2, y2, b.heading, v, w, b.own, b.time)
        x, y, g, v, w, own, t0 = self.state
        el = time - t0
        mid = g + 0.5 * w * el
        x, y = drift(x + v * el * math.cos(mid), y + v * el * math.sin(mid), own, heading, self.speed, el)
        g = g + w * el
        self.state = (x, y, g, v, w, heading, time)
        p = Contact(out, math.atan2(y, x), wrap(g), math.hypot(x, y), self.last.hops)  # type: ignore[union-attr]
        if not self._outside(p.range, p.bearing, heading):  # it would be sensed there: it is not there
            return None
        self.predicted = p
        return p
