"""world/memory.py: the world's malloc arenas capped and its free memory trimmed
(docs/benchmarks.md#recording; the soak that shows the RSS flat is benchmarks/bench_soak.py)."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

from swarm.world.memory import Trimmer


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's mallopt and malloc_trim only")
def test_arenas_capped_in_a_fresh_process():
    code = "from swarm.world.memory import limit_arenas; print(limit_arenas())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def test_trimmer_trims_when_due_and_not_before():
    t = Trimmer(period=10.0)
    t.maybe(t.due - 1.0)
    assert t.trims == 0
    t.maybe(t.due)
    assert t.trims == (0 if t.fn is None else 1)
