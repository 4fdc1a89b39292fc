"""The runtime directory, where local runs keep their sockets and credentials files
($SWARM_RUNTIME_DIR or /tmp/swarm-<uid>), and the private files in it.

A private directory is one only its user can change (created 0700, refused if another
user owns it or others may write to it); a private file is written 0600 and atomically,
and read only when it is a regular file of the user's own that nobody else may read.
Also what a local process needs to know about a run on its own machine: whether the
world that wrote a file is still there, and where to dial a wildcard listen address.
Refusals are one line (`CredentialsError`).
"""

from __future__ import annotations

import os
import secrets
import stat
import tempfile
from pathlib import Path

from swarm.contracts.identities import CredentialsError

ENV_RUNTIME_DIR = "SWARM_RUNTIME_DIR"


def read_private(path: Path) -> bytes:
    """The first MiB of `path`, a credentials file: it must be the user's own and readable
    by nobody else."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        raise CredentialsError(f"{path}: no such credentials file") from None
    except OSError as e:
        raise CredentialsError(f"{path}: cannot open: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise CredentialsError(f"{path}: not a regular file")
        if st.st_uid != os.getuid():
            raise CredentialsError(
                f"{path}: owned by uid {st.st_uid}, not by you (uid {os.getuid()}); refusing to use it"
            )
        if st.st_mode & 0o077:
            raise CredentialsError(
                f"{path}: readable by others (mode {stat.S_IMODE(st.st_mode):04o}); run `chmod 600 {path}`"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(1 << 20)
    finally:
        os.close(fd)
    return data


def write_private(path: Path, data: bytes) -> None:
    """Write `data` to `path` (mode 0600 whatever the umask), atomically (temporary + rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    try:
        try:
            os.fchmod(fd, 0o600)
            with os.fdopen(fd, "wb", closefd=False) as f:
                f.write(data)
                f.flush()
                os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:  # nothing half-written stays behind (it may hold a password)
        tmp.unlink(missing_ok=True)
        raise


def private_dir(path: Path) -> Path:
    """`path` as a directory only its user can change: created 0700 if missing (whatever the
    umask); refused with one line if another user owns it or others may write to it (they
    could replace a socket or a credentials file). Files in it are 0600 anyway."""
    path = Path(path)
    try:
        os.mkdir(path, 0o700)
        os.chmod(path, 0o700)
    except FileExistsError:
        pass
    except OSError as e:
        raise CredentialsError(f"cannot create the runtime directory {path}: {e.strerror or e}") from None
    st = os.lstat(path)
    if not stat.S_ISDIR(st.st_mode):
        raise CredentialsError(f"the runtime directory {path} is not a directory")
    if st.st_uid != os.getuid():
        raise CredentialsError(
            f"the runtime directory {path} belongs to uid {st.st_uid}, not to you "
            f"(uid {os.getuid()}); set {ENV_RUNTIME_DIR} to a directory of your own"
        )
    if st.st_mode & 0o022:
        raise CredentialsError(
            f"the runtime directory {path} is writable by others (mode "
            f"{stat.S_IMODE(st.st_mode):04o}); run `chmod 700 {path}` or set {ENV_RUNTIME_DIR}"
        )
    return path


def runtime_dir() -> Path:
    """Where local runs keep their sockets and credentials ($SWARM_RUNTIME_DIR or
    /tmp/swarm-<uid>), checked private to the user."""
    return private_dir(Path(os.environ.get(ENV_RUNTIME_DIR) or Path(tempfile.gettempdir()) / f"swarm-{os.getuid()}"))


def dial_endpoint(listen: str) -> str:
    """Where a process on the world's own machine connects to reach `listen`: a wildcard
    listen address (`tcp/0.0.0.0:P`, `tls/[::]:P`) is dialled on 127.0.0.1 (also a name
    the run's TLS certificate carries); anything else as it is."""
    proto, sep, rest = listen.partition("/")
    if proto in ("tcp", "tls") and sep:
        for wildcard in ("0.0.0.0:", "[::]:"):
            if rest.startswith(wildcard):
                return f"{proto}/127.0.0.1:{rest[len(wildcard) :]}"
    return listen


def pid_alive(pid: int) -> bool:
    """Whether process `pid` (a run's world, a host) still exists."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
