"""The output of a run's processes (`swarm logs`): where `swarm up` writes it, and reading or
following one file. `swarm up` gives each child a file in `<out>/logs/` (world.log,
agent-<id>.log; swarm/runtime/launcher.py), and `swarm spawn` puts an agent it starts there
too when the world runs on the same machine (swarm/live/control.py `spawn_log`).

A live run says where its results go (`out` in the world's info) and on which machine
(`host`): its logs are read there, from the files. On another machine they are not
reachable (nothing of a run's output goes over zenoh): a `LiveError` says on which host to
ask. A finished run's logs are read from its output directory (`logs_of_out`).
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts.errors import LiveError, UsageError

WORLD = "world"
POLL_S = 0.2  # s between looks at a followed file
END_CHECK_S = 0.5  # s between looks at whether the run has ended, while following


def parse_source(name: str | None) -> str | None:
    """`world`, an agent id as a canonical decimal string, or None (every log); UsageError for
    anything else."""
    if name is None:
        return None
    n = name.strip().lower()
    if n == WORLD:
        return WORLD
    if n.isdigit() and (n == "0" or not n.startswith("0")):
        return n
    raise UsageError(f"{name!r}: give an agent id or `world`")


def file_name(source: str) -> str:
    return "world.log" if source == WORLD else f"agent-{source}.log"


def source_of(path: Path) -> str | None:
    """`world` or the agent id of a log file's name (None: not one of a run's logs)."""
    stem = path.name.removesuffix(".log")
    if path.suffix != ".log":
        return None
    if stem == WORLD:
        return WORLD
    aid = stem.removeprefix("agent-")
    return aid if stem.startswith("agent-") and aid.isdigit() else None


def _order(source: str) -> tuple[int, int]:
    return (0, 0) if source == WORLD else (1, int(source))


@dataclass(frozen=True)
class RunLogs:
    """The logs directory of one run (`run` None: read from an output directory)."""

    dir: Path
    run: str | None = None
    agents: tuple[str, ...] = ()  # the run's agent ids (a live run's, from the world's info)

    def files(self) -> dict[str, Path]:
        """Every log there is, by source (world first, then the agents by id)."""
        found = {}
        if self.dir.is_dir():
            for p in self.dir.iterdir():
                src = source_of(p)
                if src is not None:
                    found[src] = p
        return dict(sorted(found.items(), key=lambda kv: _order(kv[0])))

    def path(self, source: str) -> Path:
        """The log of `source`; LiveError when the run has no such process or no such file."""
        p = self.dir / file_name(source)
        if source != WORLD and self.agents and source not in self.agents:
            raise LiveError(f"agent {source} is not in run {self.run} (ids: {', '.join(sorted(self.agents, key=int))})")
        if not p.is_file():
            what = "the world" if source == WORLD else f"agent {source}"
            raise LiveError(f"no log of {what} in {self.dir}" + (" (it was not started here)" if self.run else ""))
        return p


def logs_of_out(out: Path) -> RunLogs:
    """The logs of a run whose results are (or go) in `out`; UsageError when it has none."""
    d = Path(out) / "logs"
    if not d.is_dir():
        raise UsageError(f"--out {out}: no logs/ there (not a run's output directory?)")
    return RunLogs(d)


def logs_of_info(info: dict) -> RunLogs:
    """The logs of a live run from the world's info: LiveError when they are on another
    machine, or the world writes no results (started without --out)."""
    run, host, out = info.get("run"), info.get("host"), info.get("out")
    if not isinstance(out, str) or not out:
        raise LiveError(f"run {run}: its world was started without --out, so its processes write no log files")
    if host != socket.gethostname():
        raise LiveError(f"the logs of run {run} are on host {host} (in {out}/logs): run `swarm logs` there")
    return RunLogs(Path(out) / "logs", run, tuple(info.get("agents", {})))


def tail(path: Path, lines: int | None) -> tuple[list[str], int]:
    """(the last `lines` lines of `path`, all of them if None; the byte offset read up to).
    A last line still being written (no newline yet) is left for `follow`."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.rfind(b"\n") + 1
    text = data[:end].decode(errors="replace").splitlines()
    return (text if lines is None else text[-lines:] if lines > 0 else []), end


def follow(path: Path, offset: int, ended: Callable[[], bool]) -> Iterator[str]:
    """The lines written to `path` from byte `offset` on, each as soon as it is whole, until
    `ended()` (looked at every END_CHECK_S s) says the run is over: then whatever is left,
    a last line without its newline included. A file cut short starts again at its top."""
    pos, partial, checked = offset, b"", time.monotonic()
    done = False
    while True:
        try:
            size = os.path.getsize(path)
            if size < pos:  # truncated or replaced: from its top
                pos, partial = 0, b""
            if size > pos:
                with open(path, "rb") as f:
                    f.seek(pos)
                    chunk = f.read(size - pos)
                pos += len(chunk)
                *whole, partial = (partial + chunk).split(b"\n")
                for ln in whole:
                    yield ln.decode(errors="replace")
        except FileNotFoundError:
            pass
        if done:
            if partial:
                yield partial.decode(errors="replace")
            return
        now = time.monotonic()
        if now - checked >= END_CHECK_S:
            checked = now
            done = ended()  # one more read after the end: its last lines
            if done:
                continue
        time.sleep(POLL_S)
