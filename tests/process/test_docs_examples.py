"""The Python blocks of README.md's "Python API" section and of getting-started's "From Python"
run top to bottom as written, in a fresh interpreter at the repository's root: only their output
folders are moved to a temporary directory (the runs keep their lengths). A block that uses a
name before it exists, or a live run after it has ended (swarm.NoRunError, swarm.UpError), fails
here. A lockstep run goes as fast as its processes can, so a block whose live calls may reach a
run after its end would flake on a loaded machine: getting-started's reads live state only from
its realtime run (30 s of wall time, ended by its `with` block once its few calls are done)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DEADLINE_S = 600  # a bound on a hang, not an expectation of speed


def python_block(doc: Path, heading: str) -> str:
    """The first ```python block after the line that starts with `heading`."""
    text = doc.read_text()
    at = text.index(heading)
    m = re.search(r"```python\n(.*?)```", text[at:], re.S)
    assert m, f"{doc}: no python block after {heading!r}"
    return m[1]


def shortened(code: str, out: Path) -> str:
    return code.replace('"runs/', f'"{out}/')


@pytest.mark.slow
@pytest.mark.parametrize(
    "doc, heading",
    [("README.md", "## Python API"), ("docs/guides/getting-started.md", "## From Python")],
    ids=["readme", "getting-started"],
)
def test_the_python_blocks_run_top_to_bottom(doc, heading, tmp_path):
    from runtime_helpers import short_runtime_dir

    code = shortened(python_block(REPO / doc, heading), tmp_path / "runs")
    assert "swarm.up(" in code  # the block still starts runs of its own
    script = tmp_path / "block.py"
    script.write_text(code + "\nprint('BLOCK DONE')\n")
    runtime = short_runtime_dir()
    env = {**os.environ, "SWARM_RUNTIME_DIR": runtime, "MPLBACKEND": "Agg"}
    env.pop("SWARM_RUN", None)
    env.pop("SWARM_CONNECT", None)
    try:
        done = subprocess.run(
            [sys.executable, str(script)],
            cwd=REPO,
            env=env,
            capture_output=True,
            text=True,
            timeout=DEADLINE_S,
            start_new_session=True,
        )
    finally:
        import shutil

        shutil.rmtree(runtime, ignore_errors=True)
    assert done.returncode == 0, f"{doc}:\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"
    assert done.stdout.rstrip().endswith("BLOCK DONE")
