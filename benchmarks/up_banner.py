"""The first line `swarm up` prints, read back by the benchmarks that start one:

    run <run id>  endpoint <endpoint>  agents <n>  clock <clock>

(swarm/cli/up.py). Import this after putting the repository first on sys.path, as the
benchmarks do, so that `swarm` is this checkout's.
"""

from __future__ import annotations

from pathlib import Path

from swarm.runtime.procs import wait_until


def read_banner(log: Path) -> tuple[str, str] | None:
    """(run id, endpoint) from the banner in `swarm up`'s output file `log`; None before it."""
    for line in log.read_text(errors="replace").splitlines():
        if line.startswith("run ") and "endpoint" in line:
            parts = line.split()
            return parts[1], parts[3]
    return None


def wait_banner(log: Path, timeout: float) -> tuple[str, str] | None:
    """`read_banner` once `swarm up` has printed it, within `timeout` s (None after that)."""
    return wait_until(lambda: read_banner(log), timeout, 0.1) or None
