"""The files a killed world leaves in the runtime dir, and their removal.

A world removes its files when it ends; one that was SIGKILLed (or lost its machine's
power) cannot. What it leaves: `<run>.cred` (holding its pid), `<run>.sock` and
`<run>.sock.lock` (zenoh's, also `<run>.door.sock` and its lock), `.<run>.users` and the
`<run>.tls/` directory. `sweep_stale(dir)` removes them, run by run, only when their
owner is gone: a credentials file when the pid it names is not alive; a socket and its
lock when nobody holds the lock (zenoh holds it while it listens) and no live world of
that run has its credentials there (a world writes them before it opens its socket, so a
world starting meanwhile is left alone). The next world to start and `swarm runs` sweep.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
from pathlib import Path

from swarm.contracts.identities import CredentialsError
from swarm.contracts.runtime_dir import pid_alive, read_private

CRED = ".cred"
SOCKET_SUFFIXES = (".door.sock", ".sock")  # the longer first


def _owner_pid(path: Path) -> int | None | bool:
    """The pid a run's credentials file names; False when it cannot be read (keep it)."""
    try:
        pid = json.loads(read_private(path)).get("pid")
    except (CredentialsError, ValueError, AttributeError, RecursionError):
        return False
    return pid if type(pid) is int and pid > 0 else None


def _run_live(directory: Path, run: str) -> bool:
    """Whether a world of `run` may still own files here (its credentials name a live pid,
    or cannot be read: then nothing of it is touched)."""
    cred = directory / f"{run}{CRED}"
    if not cred.exists():
        return False
    pid = _owner_pid(cred)
    return pid is False or pid is None or pid_alive(pid)


def unix_socket_answers(sock: Path) -> bool:
    """Whether something accepts connections on the Unix socket `sock` (a live listener)."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.connect(str(sock))
        return True
    except OSError:
        return False
    finally:
        s.close()


def _socket_free(sock: Path, lock: Path) -> int | None | bool:
    """An fd holding `lock` (to be closed after the removal) when nobody listens on `sock`;
    None when there is no lock file and the socket refuses connections; False otherwise."""
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        return False if sock.exists() and unix_socket_answers(sock) else None
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:  # held: it listens
        os.close(fd)
        return False
    return fd


def _sweep_socket(directory: Path, sock: Path, run: str, removed: list[Path]) -> None:
    if _run_live(directory, run):
        return
    lock = sock.with_name(sock.name + ".lock")
    fd = _socket_free(sock, lock)
    if fd is False:
        return
    try:
        for p in (sock, lock):
            try:
                p.unlink()
                removed.append(p)
            except FileNotFoundError:
                pass
    finally:
        if fd is not None:
            os.close(fd)


def _socket_run(name: str) -> tuple[str, str] | None:
    """(socket file name, run) of a socket or socket lock file name; None for other files."""
    base = name.removesuffix(".lock")
    for suffix in SOCKET_SUFFIXES:
        if base.endswith(suffix) and len(base) > len(suffix):
            return base, base[: -len(suffix)]
    return None


def sweep_stale(directory: Path) -> list[Path]:
    """Remove the files of the runs in `directory` whose world is gone (see above); the
    paths removed. Best effort: what cannot be removed stays, silently."""
    directory = Path(directory)
    removed: list[Path] = []
    try:
        names = sorted(os.listdir(directory))
    except OSError:
        return removed
    for name in names:
        path = directory / name
        try:
            if name.endswith(CRED) and not name.startswith("."):
                pid = _owner_pid(path)
                if type(pid) is int and not pid_alive(pid):
                    run = name[: -len(CRED)]
                    path.unlink(missing_ok=True)
                    removed.append(path)
                    (directory / f".{run}.users").unlink(missing_ok=True)
                    tls = directory / f"{run}.tls"
                    if tls.is_dir() and not tls.is_symlink():
                        shutil.rmtree(tls, ignore_errors=True)
                        removed.append(tls)
            else:
                found = _socket_run(name)
                if found is not None and (directory / found[0]).name not in {p.name for p in removed}:
                    _sweep_socket(directory, directory / found[0], found[1], removed)
        except OSError:
            continue
    return removed
