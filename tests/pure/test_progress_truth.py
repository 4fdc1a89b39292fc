"""swarm/runtime/progress.py reads ground truth without numpy (`truth_records`): the same
records, numbers and refusals as wire.decode_truth."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.contracts import wire
from swarm.runtime.progress import truth_records


def truth(n: int, seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    return wire.encode_truth(
        123,
        1.23,
        np.arange(n) * 7 + 1,
        rng.normal(size=n) * 100,
        rng.normal(size=n),
        rng.uniform(-3, 3, n),
        np.where(np.arange(n) % 3 == 0, np.nan, rng.normal(size=n)),
        np.arange(n) - 1,
        [wire.STATES[k % len(wire.STATES)] for k in range(n)],
        5,
    )


@pytest.mark.parametrize("n", [0, 1, 6, 40])
def test_truth_records_equal_decode_truth(n):
    buf = truth(n, seed=n)
    tick, t, recs = truth_records(buf)
    tick2, t2, arr = wire.decode_truth(buf)
    assert (tick, t) == (tick2, t2) and len(recs) == len(arr) == n
    for r, a in zip(recs, arr):
        assert set(r) == set(arr.dtype.names)
        for k in arr.dtype.names:
            assert np.array_equal(np.array(r[k], dtype=arr.dtype[k]), a[k], equal_nan=True), k


def test_truth_records_refuse_what_decode_truth_refuses():
    buf = truth(3)
    for bad in (buf[:10], buf[:-1], buf + b"\0", bytes([9]) + buf[1:], buf[:1] + bytes([99]) + buf[2:]):
        with pytest.raises(wire.WireError):
            wire.decode_truth(bad)
        with pytest.raises(wire.WireError):
            truth_records(bad)
