"""The world process's native memory: what keeps its RSS flat through agent churn.

Each session that comes and goes at the hub (an agent killed and brought back, `swarm
kill`, `swarm spawn`, `swarm agents`, ...) makes zenoh's threads allocate and free link
buffers; glibc gives every thread that contends for malloc an arena of its own (up to 8 per
core), each keeps its own freed pages, and the world's RSS grew with every cycle while its
live allocations and Python objects stayed flat (benchmarks/bench_soak.py, case2 at x2 with
5 kill/spawn cycles a minute: thread arenas +1.1 MB a cycle, malloc's free bytes 2 -> 32 MB
in 7 min; none of it without the cycles). Two remedies, both glibc's own:

- `limit_arenas`: at most ARENAS malloc arenas (M_ARENA_MAX, what MALLOC_ARENA_MAX=2
  sets), so freed blocks are reused instead of kept per thread; called before any thread
  of zenoh or foxglove starts;
- `Trimmer`: `malloc_trim(0)` every PERIOD s of wall time, from the main thread between
  ticks (it also returns the free pages inside an arena, not only at its top; ~0.6 ms).

Elsewhere than glibc (musl, macOS) both do nothing.
"""

from __future__ import annotations

import ctypes
import time
from typing import Any

ARENAS = 2  # malloc arenas at most (the main one and one for every other thread)
PERIOD = 10.0  # s of wall time between trims
_M_ARENA_MAX = -8  # glibc's mallopt parameter


def _libc(name: str) -> Any:
    try:
        return getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError):  # not glibc
        return None


def limit_arenas(n: int = ARENAS) -> bool:
    """At most `n` malloc arenas from now on; True if glibc took it."""
    fn = _libc("mallopt")
    if fn is None:
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn(_M_ARENA_MAX, n) == 1


class Trimmer:
    def __init__(self, period: float = PERIOD):
        self.period = period
        self.fn = _libc("malloc_trim")
        if self.fn is not None:
            self.fn.argtypes = [ctypes.c_size_t]
            self.fn.restype = ctypes.c_int
        self.due = time.monotonic() + period
        self.trims = 0
        self.worst = 0.0  # s, the longest trim

    def maybe(self, now: float) -> None:
        """Trim if it is time (`now`: time.monotonic())."""
        if now < self.due or self.fn is None:
            return
        self.fn(0)
        self.trims += 1
        t = time.monotonic()
        self.worst = max(self.worst, t - now)
        self.due = t + self.period
