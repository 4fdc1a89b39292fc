"""The one compiled module, swarm.contracts._fastwire (the wire's hot path in C), is optional:
everything else is declared in pyproject.toml. Without a C compiler (or Python's headers) the
build says so in one line (pip shows it with -v) and goes on; swarm then runs its pure-Python
path, which gives the same bytes and the same trajectories (swarm/contracts/fastpath.py,
tests/pure/test_fastwire.py). SWARM_NO_COMPILE=1 skips the build on purpose."""

from __future__ import annotations

import os
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

FASTWIRE = Extension(
    "swarm.contracts._fastwire",
    sources=["swarm/contracts/_fastwire.c"],
    optional=True,
    extra_compile_args=["-O2", "-ffp-contract=off"] if os.name == "posix" else [],
)


class OptionalBuildExt(build_ext):
    """build_ext that never fails the install: a module that cannot be built is left out."""

    def run(self) -> None:
        if os.environ.get("SWARM_NO_COMPILE", "") not in ("", "0"):
            print("swarm: SWARM_NO_COMPILE is set: the compiled wire path is not built (pure Python)", file=sys.stderr)
            return
        try:
            super().run()
        except Exception as e:  # noqa: BLE001 (no compiler at all: distutils' errors vary)
            print(
                f"swarm: the compiled wire path was not built ({e}); swarm runs its pure-Python path", file=sys.stderr
            )

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as e:
            print(f"swarm: {ext.name} was not built ({e}); swarm runs its pure-Python path", file=sys.stderr)


setup(ext_modules=[FASTWIRE], cmdclass={"build_ext": OptionalBuildExt})
