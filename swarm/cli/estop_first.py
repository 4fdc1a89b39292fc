"""`swarm estop`'s zero twists before the command line loads (swarm/cli/__init__.py calls
`first` when argv[1] is `estop`): the run's record (swarm/robots/run_record.py `RunRecord`: the
robots' router and every robot's command topic and type) read and the zero twists sent with
the few modules that takes, before typer and the commands' modules are imported (those took
most of the e-stop's time on a loaded machine). `swarm estop` then goes on as usual and
reuses the session (`taken()`). With --robots FILE, --ready, --help or a record that cannot be found,
nothing is done here: the command does it all, as it would have."""

from __future__ import annotations

import atexit
import os
import threading
import time
from typing import Any

_sent: tuple[Any, Any, int, float] | None = None  # (the record, its open Halt, robots, s taken)
_holding: tuple[threading.Event, threading.Thread] | None = None
HOLD_GAP = 0.05  # s: zero twists again meanwhile (a running world drives on until it takes the stop)


def _option(args: list[str], name: str) -> str | None:
    for k, a in enumerate(args):
        if a == name and k + 1 < len(args):
            return args[k + 1]
        if a.startswith(name + "="):
            return a[len(name) + 1 :]
    return None


def first(args: list[str]) -> None:
    """Zero-twist the robots of the run `args` name (--run, $SWARM_RUN, else the one local
    record `swarm estop` would pick); quietly nothing when that is not clear here."""
    global _sent, _holding
    t0 = time.monotonic()
    if any(a in ("-h", "--help", "--ready", "--robots") or a.startswith("--robots=") for a in args):
        return
    try:
        # lazy: (see the module) the record's few modules only
        from swarm.robots.halt import Halt
        from swarm.robots.run_record import find_record

        record = find_record(_option(args, "--run") or os.environ.get("SWARM_RUN") or None)
        learn = any(len(t.types) > 1 for t in record.plan.targets)
        halt = Halt(record.plan, learn=learn, name="swarm_estop")
    except Exception:  # the command says why, with everything loaded
        return
    sent = halt.zero()
    _sent = (record, halt, sent, (halt.first_sent or time.monotonic()) - t0)
    quit = threading.Event()

    def hold() -> None:
        while not quit.wait(HOLD_GAP):
            halt.zero(repeat=1)

    thread = threading.Thread(target=hold, name="estop-first-hold", daemon=True)
    thread.start()
    _holding = (quit, thread)
    atexit.register(_release)  # a command that ends before it takes them (a usage error, a stop)


def _release() -> None:
    """At exit: what `first` opened and the command did not take, stopped and closed (a
    daemon thread in zenoh and an open session at the interpreter's end: its native threads
    can abort it)."""
    done = taken()
    if done is not None:
        done[1].close()


def taken() -> tuple[Any, Any, int, float] | None:
    """What `first` did: (the record, its open Halt, robots sent zero twists, s it took), once."""
    global _sent, _holding
    if _holding is not None:
        _holding[0].set()
        _holding[1].join()
        _holding = None
    done, _sent = _sent, None
    return done
