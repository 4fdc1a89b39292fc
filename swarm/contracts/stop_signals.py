"""SIGTERM and SIGINT as an exception on the main thread, which a process can hold back
while it opens or closes its zenoh session.

A session that is open when the process exits without closing it hangs the interpreter
for good (zenoh-python #434), so a stop must never land between `zenoh.open` returning
and the session being somewhere it will be closed from. `StopSignals(make)` installs
handlers that raise `make(signum)`; inside `with stops.held():` a signal is only noted,
and raised when the block ends (once the session is stored) or at a `check()`, so the
code around it has exactly one place to close it. The open itself may be `interruptible`:
a session with nothing declared on it does not hang the exit (the callbacks of declared
subscribers and queryables do), so a stop during the open is raised as it returns.
(Blocking the signals with `pthread_sigmask` would not do: another thread, zenoh's or a
BLAS library's, may take them, and Python then runs the handler on the main thread anyway.)
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from contextlib import contextmanager

SIGNALS = (signal.SIGTERM, signal.SIGINT)


def _checkpoint() -> None:
    """A Python call: where the interpreter runs the handlers of signals that came meanwhile
    (a C call that raised, as zenoh.open does on a timeout, is not such a place)."""


class StopSignals:
    """`install()` makes SIGTERM/SIGINT raise `make(signum)` (with `once`, later ones are
    ignored after the first: what stops a process must not be interrupted by a second
    Ctrl-C); `held()` defers them; `ignore()` from then on; `restore()` puts back the
    handlers there were before."""

    def __init__(self, make: Callable[[int], BaseException], once: bool = True):
        self.make = make
        self.once = once
        self.holding = 0
        self.pending: int | None = None
        self.fired = False
        self.saved: dict = {}

    def install(self) -> StopSignals:
        self.saved = {sig: signal.signal(sig, self._handler) for sig in SIGNALS}
        return self

    def _handler(self, signum, _frame) -> None:
        if self.fired and self.once:
            return
        if self.holding:
            self.pending = self.pending or signum
            return
        self._fire(signum)

    def _fire(self, signum: int) -> None:
        self.fired = True
        self.pending = None
        raise self.make(signum)

    @contextmanager
    def held(self):
        """A signal in the block is raised when the block ends (not if it raised already)."""
        self.holding += 1
        try:
            yield
        finally:
            self.holding -= 1
        if not self.holding and self.pending is not None:
            self._fire(self.pending)

    def interruptible(self, fn, *args, **kwargs):
        """`fn(*args, **kwargs)` with the stops live even inside a held block, for a blocking
        open: a stop that came while it ran is raised as it returns or fails (zenoh.open
        does not look at signals itself: it runs to its connect timeout), so it returns
        nothing, and a session it had just made, with nothing declared on it yet, goes with
        its last reference (measured: no hang at exit, its socket removed); back in the
        block, stops are held again."""
        held, self.holding = self.holding, 0
        try:
            self.check()
            return fn(*args, **kwargs)
        finally:
            _checkpoint()  # a signal that came while `fn` failed is handled here, with stops live
            self.holding = held

    def check(self) -> None:
        """Raise a held signal now (where the caller has nothing open to lose, e.g. while it
        waits before opening)."""
        if self.pending is not None:
            self._fire(self.pending)

    def ignore(self) -> None:
        """No more stops from now on (the results are being written, the session closed)."""
        for sig in SIGNALS:
            signal.signal(sig, signal.SIG_IGN)

    def restore(self) -> None:
        for sig, h in self.saved.items():
            signal.signal(sig, h)
        self.saved = {}
