"""Where a follower flies while it senses nobody it may steer by (the "search" phase).

From what the follower senses and its own heading and speed only, never the target nor
ground truth:

- **Memory.** Each tick it senses somebody, it keeps the range and bearing of the agent
  it steers by (or, when it steers by nobody, of the nearest agent it senses): the
  *anchor*. On the first tick it senses nobody, that point becomes its *home*, and from
  then on it carries home relative to itself by dead reckoning: each tick it takes off
  its own displacement, speed x elapsed time along the mean of its last two headings.
  A follower that has never sensed anybody searches about the point where it started to.
- **Pattern.** It flies about home on a circle whose radius grows with the time spent
  searching, rho(tau) = sqrt(rho0^2 + p v tau / pi): an Archimedean spiral of pitch p
  (one lap at speed v adds p to the radius; the area swept, 2 pi rho drho = p v dtau,
  grows at the rate the follower flies times the pitch). With p = range / 2 and a
  sensing range R, every point within distance D of home comes within R of the follower
  by the time rho reaches D + p / 2, and so does every agent moving on a circle of
  radius up to R - p / 2 = 3R/4 about any such point, whatever its phase: the orbits of
  a swarm about a target closer than D to home, when they are smaller than 3R/4. The
  spiral grows without bound, so the whole plane is covered in the end; a follower
  flying at v covers the disc of radius D in about pi D^2 / (p v). With unlimited
  sensing the pattern is a fixed circle of radius v / C2 about home (only a field of
  view, or nobody left alive, leaves such a follower with nobody to steer by).
- **Flying it.** The law's built-in answer to `obs.out is None` (agents.laws.search) is
  the leaders' orbit hold (agents/leader.on_orbit_command) about home at radius
  rho(tau), in the direction the follower was turning when it lost contact: from far
  away that is a straight run back to home, then the spiral.

Pure: no I/O. `SearchMemory.update` is the whole per-tick state change; the batch
brains (agents/batch.py) call its scalar helpers per searching agent, so both engines
compute the same bits.
"""

from __future__ import annotations

import math

from swarm.contracts.observation import Search
from swarm.contracts.orbits import wrap

PITCH = 0.5  # spiral pitch, in sensing ranges: p = PITCH * R (also the first radius)
MIN_TURN_MARGIN = 1.25  # radius at least this times v / max_turn_rate (the tightest circle)


def pattern(sensing_range: float | None, speed: float, c2: float,
            max_turn_rate: float | None) -> tuple[float, float, float]:
    """(rho0, pitch, rho_min) of a follower's spiral (m): see the module docstring."""
    if sensing_range is None or not math.isfinite(sensing_range):
        rho0, pitch = speed / c2, 0.0
    else:
        rho0 = pitch = PITCH * sensing_range
    rho_min = 0.0 if not max_turn_rate else MIN_TURN_MARGIN * speed / max_turn_rate
    return rho0, pitch, rho_min


def radius(rho0: float, pitch: float, rho_min: float, speed: float, tau: float) -> float:
    """rho(tau) = sqrt(rho0^2 + p v tau / pi), at least rho_min (m)."""
    return max(rho_min, math.sqrt(rho0 * rho0 + pitch * speed * tau / math.pi))


def anchor_point(rng: float, bearing: float) -> tuple[float, float]:
    """The sensed point (m) relative to the follower."""
    return rng * math.cos(bearing), rng * math.sin(bearing)


def drift(hx: float, hy: float, h0: float, h1: float, speed: float, elapsed: float) -> tuple[float, float]:
    """home relative to the follower after it moved `elapsed` s from heading h0 to h1."""
    mid = h0 + 0.5 * wrap(h1 - h0)
    d = speed * elapsed
    return hx - d * math.cos(mid), hy - d * math.sin(mid)


class SearchMemory:
    """A follower's anchor, home and search clock (module docstring); one per brain."""

    __slots__ = ("rho0", "pitch", "rho_min", "speed", "anchor", "home", "since", "direction", "prev")

    def __init__(self, sensing_range: float | None, speed: float, c2: float, max_turn_rate: float | None):
        self.rho0, self.pitch, self.rho_min = pattern(sensing_range, speed, c2, max_turn_rate)
        self.speed = speed
        self.anchor: tuple[float, float] | None = None  # (range, bearing) last sensed
        self.home: tuple[float, float] | None = None  # while searching: home minus own position
        self.since = 0.0  # time the search began (s)
        self.direction = 1
        self.prev: tuple[float, float] | None = None  # (heading, time) of the previous tick

    def update(self, steer, seen, heading: float, time: float, last_u: float) -> Search | None:
        """One tick. steer: the Contact it steers by (None: nobody); seen: else the nearest
        agent it senses with a path to a leader, which it may not take yet (None: none).
        Returns the circle to fly, None while it steers by somebody."""
        prev, self.prev = self.prev, (heading, time)
        if steer is not None:
            self.anchor = (steer.range, steer.bearing)
            self.home = None
            return None
        if self.home is None:  # nobody to steer by since this tick
            self.since, self.direction = time, (1 if last_u >= 0.0 else -1)
        if seen is not None:  # circle the rooted agent it sees, at the first radius, until it may take it
            self.anchor = (seen.range, seen.bearing)
            self.home = anchor_point(*self.anchor)
            self.since = time
        elif self.home is None:  # contact lost on this tick: home is where the anchor was
            if self.anchor is None:
                self.home = (0.0, 0.0)  # never sensed anybody: about where it is
            else:
                self.home = anchor_point(*self.anchor)
                if prev is not None:
                    self.home = drift(self.home[0], self.home[1], prev[0], heading, self.speed, time - prev[1])
        elif prev is not None:
            self.home = drift(self.home[0], self.home[1], prev[0], heading, self.speed, time - prev[1])
        return Search(self.home[0], self.home[1],
                      radius(self.rho0, self.pitch, self.rho_min, self.speed, time - self.since), self.direction)
