"""benchmarks/peers/run.py --smoke: bare zenoh, zmq over ipc and `swarm up` each complete
their lockstep ticks at N = 3 (docs/benchmarks.md#peers; the figures are the benchmark's,
not this test's)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").exists())

pytestmark = pytest.mark.slow


def test_smoke_runs_every_system(tmp_path: Path) -> None:
    pytest.importorskip("zmq", reason="pip install pyzmq")
    out = tmp_path / "peers.json"
    p = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "peers" / "run.py"), "--smoke", "--json", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert p.returncode == 0, p.stdout + p.stderr
    runs = json.loads(out.read_text())["runs"]
    assert sorted(r["system"] for r in runs) == ["swarm", "zenoh", "zmq"]
    for r in runs:
        assert r["ok"], r
        assert r["ticks"] >= 50, r
        assert r["ticks_per_second"] > 0, r
    assert "bare zenoh" in p.stdout and "`swarm up`" in p.stdout
