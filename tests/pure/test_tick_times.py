"""world/tick_times.py: the world's tick durations in a bounded histogram (summary.json's
`tick_ms`), against the exact figures of the durations kept."""

from __future__ import annotations

import math
import random
import statistics

import pytest

from swarm.world.tick_times import BINS, HIGH, LOW, RATIO, TickTimes, bin_of


def nearest_rank(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[max(1, math.ceil(q * len(s))) - 1]


def test_no_tick_no_figures():
    t = TickTimes()
    assert t.summary_ms() is None and t.quantile(0.5) is None and t.mean() is None


def test_the_bins_are_ratio_wide_from_low_to_high():
    assert bin_of(0.0) == bin_of(LOW) == 0 and bin_of(HIGH * 10) == bin_of(math.inf) == BINS - 1
    assert LOW * RATIO ** (BINS - 1) < HIGH <= LOW * RATIO**BINS
    for k in (1, 10, 500, BINS - 2):
        lo = LOW * RATIO**k
        assert bin_of(lo * 1.001) == k and bin_of(lo * RATIO * 0.999) == k


@pytest.mark.parametrize("seed", range(5))
def test_quantiles_are_within_one_percent_and_the_rest_exact(seed):
    rs = random.Random(seed)
    xs = [rs.lognormvariate(math.log(1e-3), 1.0) for _ in range(5000)] + [0.25]  # ms ticks, one stall
    t = TickTimes()
    for x in xs:
        t.add(x)
    assert t.n == len(xs) and sum(t.counts) == len(xs)
    for q in (0.01, 0.5, 0.9, 0.99, 0.999, 1.0):
        got, want = t.quantile(q), nearest_rank(xs, q)
        assert got is not None and abs(got / want - 1) <= math.sqrt(RATIO) - 1 + 1e-12, (q, got, want)
    assert t.quantile(1.0) == max(xs) == t.high and t.low == min(xs)
    assert t.mean() == pytest.approx(statistics.fmean(xs), rel=1e-12)
    ms = t.summary_ms()
    assert ms is not None and list(ms) == ["p50", "p99", "max", "mean"]
    assert ms["max"] == round(250.0, 4) and ms["p50"] == round(1e3 * t.quantile(0.5), 4)


def test_one_duration_is_every_figure_exactly():
    t = TickTimes()
    t.add(0.0123)
    assert t.summary_ms() == {"p50": 12.3, "p99": 12.3, "max": 12.3, "mean": 12.3}


def test_durations_out_of_range_count_at_the_ends_and_stay_exact_in_max_and_mean():
    t = TickTimes()
    for x in (0.0, 1e-9, 2 * HIGH):
        t.add(x)
    assert t.counts[0] == 2 and t.counts[-1] == 1
    assert (
        t.quantile(0.5) <= LOW * RATIO
        and t.quantile(1.0) == 2 * HIGH
        and t.mean() == pytest.approx((1e-9 + 2 * HIGH) / 3)
    )


@pytest.mark.slow
def test_memory_is_bounded_whatever_the_ticks():
    t = TickTimes()
    for k in range(200_000):
        t.add(1e-4 * (1 + k % 977))
    assert len(t.counts) == BINS < 2000 and t.n == 200_000
