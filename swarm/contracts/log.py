"""Diagnostics of every swarm process on stderr, with the standard library's `logging`.

Each process sets it up once (`setup(name)`): the `swarm` command for its command (`swarm up`:
"up"), the world process ("world"), an agent process ("agent 3"), `swarm robots sim`
("fleet"). Every module logs through `logging.getLogger(__name__)` (a child of the "swarm"
logger, which holds the one handler), so one setup covers them all. A line looks as these
processes' lines always looked, which users, the launcher and the tests read:

    [world] run case2-734b0c listening on unixsock-stream//tmp/swarm-0/case2-734b0c.sock
    swarm world: cannot listen on tcp/127.0.0.1:7: Address in use

INFO and DEBUG lines (progress, notes) read "[name] ...", WARNING and ERROR lines (why a process
stops, what a user must know) "swarm name: ..." (swarm/runtime/supervision.py takes a log's
last line as the cause of an exit only when it reads so). A message that carries its own
prefix is logged with `extra=VERBATIM`.

The level: `setup(name, level)`, else $SWARM_LOG_LEVEL (DEBUG, INFO, WARNING, ERROR, or a
number), else INFO. `swarm -v` / `swarm -q` set that variable (`set_level_env`), so the
processes a command starts (the world and agents of `swarm up`) inherit it. Standard library
only (every process imports it, an agent's among the first).
"""

from __future__ import annotations

import logging
import os
import sys
from typing import Any

ENV_LEVEL = "SWARM_LOG_LEVEL"
ROOT = "swarm"  # the logger that holds the handler; modules log to its children (__name__)
LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
VERBATIM = {"verbatim": True}  # `extra=VERBATIM`: the message is the whole line


class LevelError(ValueError):
    pass


def parse_level(value: str | int) -> int:
    """A level from its name (any case) or number; LevelError naming the accepted ones."""
    if isinstance(value, int):
        return value
    text = value.strip()
    if text.isdigit():
        return int(text)
    if text.upper() in LEVELS:
        return int(getattr(logging, text.upper()))
    raise LevelError(f"{ENV_LEVEL}={value!r} is not a log level (one of {', '.join(LEVELS)}, or a number)")


class _Stderr(logging.StreamHandler):
    """Writes to `sys.stderr` as it is when each line is written (pytest's capture, rich's live
    display, a forked agent's log file), never to the stream it saw when it was made."""

    def __init__(self) -> None:
        super().__init__()

    @property
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:  # (StreamHandler.__init__ sets it)
        pass


class Prefixed(logging.Formatter):
    """ "[name] message" below WARNING, "swarm name: message" from WARNING on; a record with
    `verbatim` set as it is; a traceback (`log.exception`) on the lines after."""

    def __init__(self, name: str):
        super().__init__()
        self.name = name

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage()
        if not getattr(record, "verbatim", False):
            msg = f"swarm {self.name}: {msg}" if record.levelno >= logging.WARNING else f"[{self.name}] {msg}"
        if record.exc_info:
            msg += "\n" + self.formatException(record.exc_info)
        return msg


def env_level(default: int = logging.INFO) -> tuple[int, str | None]:
    """The level $SWARM_LOG_LEVEL asks for (`default` when unset or empty) and, when it is not a
    level, why (then `default`)."""
    raw = os.environ.get(ENV_LEVEL, "")
    if not raw.strip():
        return default, None
    try:
        return parse_level(raw), None
    except LevelError as e:
        return default, f"{e}: {logging.getLevelName(default)} used"


def setup(name: str, level: int | str | None = None) -> logging.Logger:
    """Set up this process's diagnostics: one handler on stderr with the prefix `name`, at
    `level` (else $SWARM_LOG_LEVEL's, else INFO). Called again (a forked agent, a test, `swarm
    world` after the `swarm` command's own setup) it replaces the handler: the last name
    counts. The "swarm" logger, returned."""
    root = logging.getLogger(ROOT)
    complaint = None
    if level is None:
        lvl, complaint = env_level()
    else:
        lvl = parse_level(level)
    for h in list(root.handlers):
        if isinstance(h, _Stderr):
            root.removeHandler(h)
    handler = _Stderr()
    handler.setFormatter(Prefixed(name))
    root.addHandler(handler)
    root.setLevel(lvl)
    root.propagate = False  # one line per record, whatever the root logger has
    if complaint is not None:
        root.warning(complaint)
    return root


def set_level_env(level: str) -> None:
    """Ask this process and the processes it starts from now on for `level` ($SWARM_LOG_LEVEL)."""
    parse_level(level)
    os.environ[ENV_LEVEL] = level


def prefix() -> str | None:
    """The prefix the process's diagnostics carry ("world", "agent 3"), None before `setup`."""
    for h in logging.getLogger(ROOT).handlers:
        if isinstance(h, _Stderr) and isinstance(h.formatter, Prefixed):
            return h.formatter.name
    return None
