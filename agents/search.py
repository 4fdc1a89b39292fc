"""Where a follower flies while it senses nobody it may steer by (the "search" phase).

From what the follower senses and its own heading and speed only, never the target nor
ground truth:

- **Memory.** Each tick it senses the agent it steers by, it keeps that agent's range and
  bearing: the *anchor*. From the first tick it no longer does (it coasts on a
  prediction, agents/coast.py, or has nobody), that point becomes its *home*, carried
  relative to itself by dead reckoning: each tick it takes off its own displacement,
  speed x elapsed time along the mean of its last two headings. A follower that has never
  sensed anybody searches about the point where it started to.
- **Pattern.** It flies about home on a circle whose radius follows the time spent
  searching along an Archimedean spiral of pitch p: rho = sqrt(rho0^2 + p v s / pi) after
  s s (one lap at speed v adds p to the radius). With p = range / 2 = rho0 (the default
  SelectionTuning.search_pitch, 0.5 sensing ranges; swarm/contracts/tuning.py), every point
  within distance D of home comes within the range R of the follower by the time rho
  reaches D + p / 2, and so does every agent moving on a circle of radius up to
  R - p / 2 = 3R/4 about such a point, whatever its phase. The spiral breathes: out to
  4 rho0 (search_first_out) and back in, then out to 8 rho0 (x search_growth, 2) and back,
  and so on, so that it passes again
  and again, at other phases, over the region near home where the swarm most likely is,
  and still covers the whole plane in the end. With unlimited sensing the pattern is a
  fixed circle of radius v / C2 about home (only a field of view, or nobody left alive,
  leaves such a follower with nobody to steer by).
- **Closing in.** A rooted agent it senses but may not take yet (out of reach, or not
  feasible) becomes home, anew every tick, with a tight circle (SEEN x rho0): the
  follower closes in on it until it may take it.
- **Flying it.** The law's built-in answer to `obs.out is None` (swarm.agents.laws.search) is
  the leaders' orbit hold (agents/leader.on_orbit_command) about home at that radius, in
  the direction the follower was turning when it lost contact: from far away that is a
  straight run back to home, then the spiral.

Pure: no I/O. `SearchMemory.update` is the whole per-tick state change; the batch
brains (agents/batch.py) call its scalar helpers per searching agent, so both engines
compute the same bits.
"""

from __future__ import annotations

import math

from swarm.contracts.frames import Contact
from swarm.contracts.observation import Search
from swarm.contracts.orbits import wrap
from swarm.contracts.tuning_ticks import DEFAULT as DEFAULT_TUNING
from swarm.contracts.tuning_ticks import Tuning, TuningTicks

DEFAULT = DEFAULT_TUNING  # the search's pitch and breaths, when not given
SEEN = 0.25  # the circle about a rooted agent it sees but may not take yet, in first radii
MIN_TURN_MARGIN = 1.25  # radius at least this times v / max_turn_rate (the tightest circle)


def pattern(
    sensing_range: float | None, speed: float, c2: float, max_turn_rate: float | None, pitch: float
) -> tuple[float, float, float]:
    """(rho0, pitch, rho_min) of a follower's spiral (m): see the module docstring; pitch:
    SelectionTuning.search_pitch, in sensing ranges."""
    if sensing_range is None or not math.isfinite(sensing_range):
        rho0, pitch = speed / c2, 0.0
    else:
        rho0 = pitch = pitch * sensing_range
    rho_min = 0.0 if not max_turn_rate else MIN_TURN_MARGIN * speed / max_turn_rate
    return rho0, pitch, rho_min


def radius(
    rho0: float,
    pitch: float,
    rho_min: float,
    speed: float,
    tau: float,
    first_out: float = DEFAULT.search_first_out,
    growth: float = DEFAULT.search_growth,
) -> float:
    """The search circle's radius after tau s of searching (m): a spiral of pitch p that
    breathes, out from rho0 to first_out x rho0 x growth^k and back in again, k = 0, 1, 2...
    (4, 8, 16... x rho0 by default): on the way out rho = sqrt(rho0^2 + p v s / pi) after
    s s, and the same backwards on the way in. At least rho_min. Without a pitch
    (unlimited sensing): rho0."""
    if pitch <= 0.0:
        return max(rho_min, rho0)
    rate = pitch * speed / math.pi  # area swept per s, over pi (m^2/s)
    s, top = tau, first_out * rho0
    while True:
        leg = (top * top - rho0 * rho0) / rate  # s from rho0 out to `top`
        if s <= 2.0 * leg:
            break
        s -= 2.0 * leg
        top *= growth
    if s > leg:
        s = 2.0 * leg - s
    return max(rho_min, math.sqrt(rho0 * rho0 + rate * s))


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

    __slots__ = (
        "rho0",
        "pitch",
        "rho_min",
        "breaths",
        "speed",
        "anchor",
        "home",
        "searching",
        "since",
        "direction",
        "prev",
    )

    def __init__(
        self,
        sensing_range: float | None,
        speed: float,
        c2: float,
        max_turn_rate: float | None,
        tuning: Tuning | TuningTicks = DEFAULT,
    ):
        self.rho0, self.pitch, self.rho_min = pattern(sensing_range, speed, c2, max_turn_rate, tuning.search_pitch)
        self.breaths = (tuning.search_first_out, tuning.search_growth)
        self.speed = speed
        self.anchor: tuple[float, float] | None = None  # (range, bearing) last sensed
        self.home: tuple[float, float] | None = None  # the anchor minus own position since, if carried
        self.searching = False
        self.since = 0.0  # time the search began (s)
        self.direction = 1
        self.prev: tuple[float, float] | None = None  # (heading, time) of the previous tick

    def update(
        self,
        steer: Contact | None,
        seen: Contact | None,
        heading: float,
        time: float,
        last_u: float,
        predicted: bool = False,
    ) -> Search | None:
        """One tick. steer: the Contact it steers by (None: nobody), `predicted` when that
        is a coasting prediction (agents/coast.py: not a sighting, home is carried on);
        seen: with nobody to steer by, the nearest agent it senses with a path to a leader,
        which it may not take yet (None: none). Returns the circle to fly, None while it
        steers by somebody."""
        prev, self.prev = self.prev, (heading, time)
        if steer is not None and not predicted:
            self.anchor = (steer.range, steer.bearing)
            self.home = None
            self.searching = False
            return None
        if seen is not None:  # circle the rooted agent it sees, at the first radius, until it may take it
            self.anchor = (seen.range, seen.bearing)
            self.home = anchor_point(*self.anchor)
        elif self.home is None:  # the anchor was sensed on the previous tick (or never)
            if self.anchor is None:
                self.home = (0.0, 0.0)  # never sensed anybody: about where it is
            else:
                self.home = anchor_point(*self.anchor)
                if prev is not None:
                    self.home = drift(self.home[0], self.home[1], prev[0], heading, self.speed, time - prev[1])
        elif prev is not None:
            self.home = drift(self.home[0], self.home[1], prev[0], heading, self.speed, time - prev[1])
        if steer is not None:  # coasting: home carried along, the law flies by the prediction
            self.searching = False
            return None
        if not self.searching:
            self.searching, self.direction = True, (1 if last_u >= 0.0 else -1)
            self.since = time
        if seen is not None:  # close in on it: a tight circle about where it is now
            self.since = time
            return Search(self.home[0], self.home[1], max(self.rho_min, SEEN * self.rho0), self.direction)
        return Search(
            self.home[0],
            self.home[1],
            radius(self.rho0, self.pitch, self.rho_min, self.speed, time - self.since, *self.breaths),
            self.direction,
        )
