"""The distribution claims one import name: a wheel built from the tree holds `swarm` (with
`swarm.agents` and `swarm.world` from the agents/ and world/ folders) and nothing else at the
top, and `swarm up` runs from that wheel alone (not from the source tree)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow


def build_wheel(tmp_path_factory, env: dict | None = None) -> tuple[Path, str]:
    """A wheel built offline from a copy of the tracked files (the build writes next to them),
    and what the build printed."""
    src = tmp_path_factory.mktemp("src")
    files = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    for name in filter(None, files.decode().split("\0")):
        here, there = REPO / name, src / name
        there.parent.mkdir(parents=True, exist_ok=True)
        if here.is_symlink():
            there.symlink_to(os.readlink(here))
        elif here.is_file():
            shutil.copy2(here, there)
    out = tmp_path_factory.mktemp("dist")
    build = "from setuptools import build_meta as b; import sys; print(b.build_wheel(sys.argv[1]))"
    p = subprocess.run([sys.executable, "-c", build, str(out)], cwd=src, capture_output=True, text=True, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    return out / p.stdout.strip().splitlines()[-1], p.stdout + p.stderr


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    return build_wheel(tmp_path_factory)[0]


def compiled_modules(wheel: Path) -> list[str]:
    return [n for n in zipfile.ZipFile(wheel).namelist() if n.endswith((".so", ".pyd"))]


def test_the_wheel_holds_the_compiled_path_where_a_compiler_exists(wheel):
    if shutil.which(os.environ.get("CC", "cc")) is None:
        pytest.skip("no C compiler here")
    assert [n.rsplit("/", 1)[0] for n in compiled_modules(wheel)] == ["swarm/contracts"]
    assert "swarm/contracts/_fastwire.pyi" in zipfile.ZipFile(wheel).namelist()


def test_a_machine_without_a_compiler_builds_a_pure_wheel_that_says_so(tmp_path_factory, tmp_path):
    """CC names no compiler (a machine without one, simulated): the build succeeds, says in
    one line that the compiled path was not built, and the installed wheel runs the pure path."""
    env = {**os.environ, "CC": str(tmp_path / "no-such-cc")}
    pure, printed = build_wheel(tmp_path_factory, env)
    assert compiled_modules(pure) == []
    assert "the compiled wire path was not built" in printed or "was not built" in printed, printed[-3000:]
    site = tmp_path / "site"
    install = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", "--target", str(site)]
    subprocess.run([*install, str(pure)], check=True)
    code = "from swarm.contracts import fastpath; print(fastpath.path)"
    clean = {k: v for k, v in os.environ.items() if k not in ("SWARM_PURE_PYTHON", "CC")}
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env={**clean, "PYTHONPATH": str(site)},
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0 and out.stdout.startswith("pure Python (the compiled module was not built"), out


def test_the_wheel_holds_one_top_level_package(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith((".dist-info", ".data"))}
    assert tops == {"swarm"}
    for module in ("swarm/agents/process.py", "swarm/world/main.py", "swarm/cli/main.py", "swarm/py.typed"):
        assert module in names


def test_swarm_up_runs_from_the_installed_wheel(wheel, tmp_path, rt):
    """Installed (files only; the dependencies are this environment's), run from a directory
    that is not the tree: `import agents` / `import world` fail, `swarm up` works, and its
    processes use the installed code."""
    site = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-index",
            "--target",
            str(site),
            str(wheel),
        ],
        check=True,
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**rt.env, "PYTHONPATH": str(site)}
    for name in ("agents", "world"):
        p = subprocess.run(
            [sys.executable, "-c", f"import {name}"], cwd=elsewhere, env=env, capture_output=True, text=True
        )
        assert p.returncode != 0 and "No module named" in p.stderr
    where = subprocess.run(
        [sys.executable, "-c", "import swarm.agents.process as m; print(m.__file__)"],
        cwd=elsewhere,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert where.startswith(str(site))
    shutil.copy(REPO / "scenarios" / "case2.toml", elsewhere / "case2.toml")
    up = rt.tracker.spawn(
        [sys.executable, "-m", "swarm", "up", "case2.toml", "--duration", "1", "--out", "run", "--no-plots"],
        "up",
        cwd=elsewhere,
        env=env,
    )
    assert up.popen.wait(timeout=240) == 0, up.text()[-3000:]
    summary = json.loads((elsewhere / "run" / "summary.json").read_text())
    assert summary["completed"] and len(summary["agents"]) == 6
