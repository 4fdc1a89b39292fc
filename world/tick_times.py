"""How long the world's ticks take in wall time, in bounded memory: `TickTimes`.

The world process (world/clock.py) adds every tick's wall duration; summary.json gives
`tick_ms` from it (docs/reference/outputs.md#summary). A run may last millions of ticks,
so the durations are not kept: each one counts in a bin of a fixed log-spaced histogram
(bins RATIO wide from LOW s up, BINS of them, ~9 KB), and a quantile is the geometric
middle of its bin, within a factor of sqrt(RATIO) (1%) of the true one; the count, the
sum, the minimum and the maximum are exact. Adding a duration costs a few hundred ns.
"""

from __future__ import annotations

import math

LOW = 1e-6  # s: durations up to this count in the first bin
RATIO = 1.02  # upper / lower bound of a bin
HIGH = 1e4  # s: durations past this count in the last bin (the maximum stays exact)
BINS = math.ceil(math.log(HIGH / LOW) / math.log(RATIO))
_LOG_LOW = math.log(LOW)
_PER_LOG = 1.0 / math.log(RATIO)  # bins per unit of natural log


def bin_of(t: float) -> int:
    """The bin a duration of `t` s counts in: [LOW * RATIO**k, LOW * RATIO**(k + 1)) is bin k,
    anything up to LOW is bin 0 and anything past HIGH the last."""
    if t <= LOW:
        return 0
    if t >= HIGH:
        return BINS - 1
    return min(int((math.log(t) - _LOG_LOW) * _PER_LOG), BINS - 1)


class TickTimes:
    """Tick durations (s) as a histogram (see the module): `add` each, then `quantile`,
    `mean`, `summary_ms`."""

    __slots__ = ("counts", "n", "total", "low", "high")

    def __init__(self) -> None:
        self.counts = [0] * BINS
        self.n = 0
        self.total = 0.0  # s, the sum of the durations
        self.low = math.inf  # s, the shortest
        self.high = 0.0  # s, the longest

    def add(self, t: float) -> None:
        """One tick took `t` s of wall time (`bin_of`, inlined: this runs every tick)."""
        self.n += 1
        self.total += t
        if t > self.high:
            self.high = t
        if t < self.low:
            self.low = t
        if t <= LOW:
            self.counts[0] += 1
        elif t >= HIGH:
            self.counts[-1] += 1
        else:
            k = int((math.log(t) - _LOG_LOW) * _PER_LOG)
            self.counts[k if k < BINS else BINS - 1] += 1

    def quantile(self, q: float) -> float | None:
        """The q-quantile (0 < q <= 1) of the durations, s, by nearest rank: the middle of the
        bin holding the ceil(q n)-th shortest, within the exact minimum and maximum (the
        shortest and the longest themselves exactly); None when no tick was added."""
        if not self.n:
            return None
        rank = max(1, math.ceil(q * self.n))
        if rank >= self.n:
            return self.high
        if rank == 1:
            return self.low
        seen = 0
        for k, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                mid = LOW * RATIO ** (k + 0.5)
                return min(max(mid, self.low), self.high)
        return self.high  # not reached: the counts sum to n

    def mean(self) -> float | None:
        return self.total / self.n if self.n else None

    def summary_ms(self) -> dict[str, float] | None:
        """summary.json's `tick_ms`: {"p50", "p99", "max", "mean"} in ms (to 0.1 us), or None
        when no tick ran."""
        if not self.n:
            return None
        p50, p99, mean = self.quantile(0.5), self.quantile(0.99), self.mean()
        assert p50 is not None and p99 is not None and mean is not None
        return {k: round(1e3 * v, 4) for k, v in (("p50", p50), ("p99", p99), ("max", self.high), ("mean", mean))}
