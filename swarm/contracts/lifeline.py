"""Lifelines between the processes of a run: what a child does when its launcher dies,
and how an agent tells a world that is gone from one that has stopped answering.

- `tie_to_launcher()`: a process started by `swarm up` asks the kernel (Linux
  `prctl(PR_SET_PDEATHSIG)`) for SIGTERM when the launcher dies, even by SIGKILL; it
  then stops as on any SIGTERM (the world writes its results). The launcher passes its
  pid in `LAUNCHER_PID_ENV`; if the parent is not that pid any more, the launcher died
  before the request, and the process signals itself at once. Elsewhere (not Linux) it
  does nothing and returns False.
- `exit_status(code)`: an exit status in words, the same for the launcher and the world.
- `endpoint_refuses(endpoint)`: whether nothing listens on a zenoh endpoint any more
  (connection refused, socket file gone): a world that was killed or ended. A stopped
  (SIGSTOP) or cut-off world still accepts connections in the kernel or does not answer
  at all, which is not a refusal.

Standard library only; imported by the world and the agents (docs/reference/protocol.md#world-gone, #launcher-gone).
"""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import sys
from collections.abc import Mapping
from typing import Any

LAUNCHER_PID_ENV = "SWARM_LAUNCHER_PID"
PR_SET_PDEATHSIG = 1


def tie_to_launcher(sig: int = signal.SIGTERM, env: Mapping[str, str] | None = None) -> bool:
    """Get `sig` when the launcher named in $SWARM_LAUNCHER_PID dies; True when armed."""
    env = os.environ if env is None else env
    want = env.get(LAUNCHER_PID_ENV)
    if not want or not want.isdigit() or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() != int(want):  # the launcher died before we asked: act as if told now
        os.kill(os.getpid(), sig)
    return True


def exit_status(code: int) -> str:
    """'exit code 1' or 'killed by SIGSEGV' (a negative code: killed by that signal)."""
    if code >= 0:
        return f"exit code {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def endpoint_socket(endpoint: str, timeout: float) -> Any:
    """(a plain socket, the address to connect it to) for the listener under `endpoint`
    (tcp/HOST:PORT and tls/HOST:PORT: its TCP listener; unixsock-stream/PATH), with
    `timeout`; None when `endpoint` cannot be parsed."""
    kind, _, rest = endpoint.partition("/")
    rest = rest.split("#")[0].split("?")[0]
    addr: str | tuple[str, int]
    try:
        if kind == "unixsock-stream":
            s, addr = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM), rest
        elif kind in ("tcp", "tls"):
            host, _, port = rest.rpartition(":")
            host = host.strip("[]")
            addr = (host, int(port))
            s = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
        else:
            return None
    except (ValueError, OSError):
        return None
    s.settimeout(timeout)
    return s, addr


def endpoint_refuses(endpoint: str, timeout: float = 0.5) -> bool:
    """True when a connection to `endpoint` (tcp/HOST:PORT, tls/HOST:PORT, probed as the TCP
    listener under it, or unixsock-stream/PATH) is refused or its socket file is gone;
    False when it connects, times out or cannot be parsed (nothing proves the world is gone)."""
    made = endpoint_socket(endpoint, timeout)
    if made is None:
        return False
    s, addr = made
    try:
        s.connect(addr)
        return False
    except (ConnectionRefusedError, FileNotFoundError):
        return True
    except OSError:  # timeout, unreachable, full backlog: not a proof
        return False
    finally:
        s.close()
