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

`CliStops` is the command line's own: installed by the `swarm` entry point before anything
else, it makes a stop at any moment of a command one line and exit 128 + signum.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

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

    def _handler(self, signum: Any, _frame: Any) -> None:
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
    def held(self) -> Iterator[Any]:
        """A signal in the block is raised when the block ends (not if it raised already)."""
        self.holding += 1
        try:
            yield
        finally:
            self.holding -= 1
        if not self.holding and self.pending is not None:
            self._fire(self.pending)

    def interruptible(self, fn: Any, *args: Any, **kwargs: Any) -> Any:
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


class Stopped(KeyboardInterrupt):
    """SIGINT or SIGTERM (`signum`) in a command of the command line, raised by `CliStops`: a
    KeyboardInterrupt, so that a command that ends on Ctrl-C (`swarm watch`, `swarm study`...)
    ends the same way on SIGTERM."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class CliStops:
    """SIGINT and SIGTERM in the `swarm` command line, from the first line of its entry point
    (swarm/cli/__init__.py, before the heavy imports) to its exit. Whatever the moment, a stop
    is one line on stderr ("swarm up: stopped by SIGINT") and exit 128 + signum, never a
    traceback:

    - while it starts (imports, building the commands, parsing the options) nothing has been
      started that needs an end: the process says its line and exits at once (`os._exit`);
    - while a command runs (`running()` .. `ending()`, swarm/cli/errors.py's `mapped`), the
      stop is raised as `Stopped` (a KeyboardInterrupt: what ends on Ctrl-C ends on either),
      once; a command that takes the signals over (`swarm up`'s launcher, the world, an agent)
      installs its own handlers and puts these back after. A `Stopped` that Python could not
      raise (it came in a weakref callback or a `__del__`, where exceptions are only printed:
      Python's own KeyboardInterrupt is lost there, and with it the stop) ends the process
      at once instead;
    - once the command has returned (its output is complete; the interpreter may still be
      closing), the process exits at once: a second Ctrl-C ends a hung exit too.

    Before the interpreter runs swarm's first line (its own start-up, ~30 ms, 0.1 s or more
    on a loaded machine), a signal is Python's: SIGTERM ends the process silently, SIGINT
    may print the interpreter's own KeyboardInterrupt."""

    STARTING, RUNNING, ENDING = "starting", "running", "ending"

    def __init__(self, prog: str = "swarm"):
        self.prog = prog
        self.phase = self.STARTING
        self.signum: int | None = None  # the stop that came, if one did
        self.raised: Stopped | None = None
        self._hook = sys.unraisablehook

    def install(self) -> CliStops:
        for sig in SIGNALS:
            signal.signal(sig, self._handler)
        self._hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        return self

    def line(self, signum: int) -> str:
        return f"{self.prog}: stopped by {signal_name(signum)}"

    def exit_code(self) -> int:
        return 128 + (self.signum or signal.SIGINT)

    def running(self) -> None:
        """The command runs: a stop is raised (`Stopped`) from now on."""
        if self.phase == self.STARTING:
            self.phase = self.RUNNING

    def ending(self) -> None:
        """The command has returned: a stop from now on exits at once."""
        self.phase = self.ENDING

    def _handler(self, signum: int, _frame: Any) -> None:
        if self.phase != self.RUNNING:
            self.exit_now(signum)
        if self.signum is not None:
            return  # once: the stop is under way (a second Ctrl-C must not interrupt its ending)
        self.signum = signum
        self.raised = Stopped(signum)
        raise self.raised

    def exit_now(self, signum: int) -> None:
        """Say the line and exit 128 + signum, now (no `finally`, no atexit: nothing of the
        command's is running, or it has been given its chance)."""
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # (a flush under way in the main thread: what it had is lost)
                pass
        try:
            os.write(2, (self.line(signum) + "\n").encode())
        finally:
            os._exit(128 + signum)

    def _unraisable(self, u: Any) -> None:
        if self.raised is not None and u.exc_value is self.raised:
            self.exit_now(self.raised.signum)  # the stop was lost where it came (see the class)
        self._hook(u)
