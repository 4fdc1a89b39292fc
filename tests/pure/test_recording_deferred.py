"""world/recording.py's DeferredRecorder: the world writes each tick one step late (after it
has sent the next frames); what reaches the recorder, and in what order, must not change."""

from __future__ import annotations

import numpy as np

from swarm.world.recording import DeferredRecorder


class Calls:
    """A recorder that notes every call."""

    def __init__(self):
        self.calls: list[tuple] = []
        self.rows = 0

    def record(self, tick, time, x, y, heading, u, out, alive, missed=0, follow=None):
        self.calls.append(
            (
                "record",
                tick,
                time,
                x.tolist(),
                y.tolist(),
                heading.tolist(),
                u.tolist(),
                out.tolist(),
                alive.tolist(),
                missed,
                None if follow is None else follow.tolist(),
            )
        )
        self.rows = tick + 1

    def event(self, ev):
        self.calls.append(("event", ev["kind"]))

    def close(self):
        self.calls.append(("close",))


def _tick(rec, k, x, follow=None):
    rec.record(k, k * 0.01, x, x + 1, x * 0, x * 2, np.array([2, 1]), np.array([True, True]), k % 2, follow)


def test_the_calls_reach_the_recorder_in_the_same_order_with_the_values_of_their_time():
    direct, inner = Calls(), Calls()
    deferred = DeferredRecorder(inner)
    for rec in (direct, deferred):
        x = np.array([0.0, 1.0])
        follow = np.array([0, 2], dtype=np.int8)
        _tick(rec, 0, x, follow)
        x += 5.0  # changed in place after the tick was recorded: the record keeps the old values
        follow[1] = 4
        rec.event({"kind": "drop"})
        _tick(rec, 1, x)
        assert rec.rows == 2  # reading it writes what is pending
        _tick(rec, 2, x)
        if rec is deferred:
            assert len(inner.calls) == 3  # tick 2 waits for a flush
            deferred.flush()
            deferred.flush()  # nothing twice
        rec.close()
    assert inner.calls == direct.calls
    assert [c[0] for c in inner.calls] == ["record", "event", "record", "record", "close"]
    assert inner.calls[0][3] == [0.0, 1.0]
    assert inner.calls[0][-1] == [0, 2] and inner.calls[2][-1] is None  # the follow states of their time


class Interrupted(Calls):
    """A recorder whose first write is interrupted (the world's Stop, raised by a signal)
    after the row reached it."""

    def __init__(self):
        super().__init__()
        self.interrupt = True

    def record(self, *args, **kwargs):
        super().record(*args, **kwargs)
        if self.interrupt:
            self.interrupt = False
            raise KeyboardInterrupt


def test_a_write_interrupted_by_a_signal_is_written_again_not_lost():
    inner = Interrupted()
    rec = DeferredRecorder(inner)
    _tick(rec, 0, np.array([0.0, 1.0]))
    try:
        rec.flush()
    except KeyboardInterrupt:
        pass
    assert rec.rows == 1  # flushed again on the way out: tick 0 twice, which counts once
    assert [c[1] for c in inner.calls] == [0, 0]
