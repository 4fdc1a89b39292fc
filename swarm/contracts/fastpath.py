"""Whether the wire's hot path runs compiled: swarm.contracts._fastwire, a C module built by
`pip install` where a C compiler exists (setup.py), encodes and decodes sensor frames and
picks the nearest contact. Where it was not built, or with SWARM_PURE_PYTHON=1 in the
environment (inherited by every process of a run), the pure-Python functions run instead:
they are the reference, and both give the same bytes, objects and trajectories
(tests/pure/test_fastwire.py). `swarm --version` says which path this installation runs."""

from __future__ import annotations

import os
from types import ModuleType

PURE_ENV = "SWARM_PURE_PYTHON"
API = 3  # the compiled module's API this code calls (FASTWIRE_API in _fastwire.c)


def _load() -> tuple[ModuleType | None, str]:
    if os.environ.get(PURE_ENV, "") not in ("", "0"):
        return None, f"pure Python ({PURE_ENV} is set)"
    try:
        from swarm.contracts import _fastwire  # lazy: optional (built only where a C compiler was)
    except ImportError:
        return None, "pure Python (the compiled module was not built: no C compiler at install?)"
    built = getattr(_fastwire, "API", 1)
    if built != API:  # built from another checkout (pip install -e, then a pull)
        return None, f"pure Python (the compiled module is of API {built}, this code needs {API}: install again)"
    return _fastwire, "compiled (swarm.contracts._fastwire)"


compiled, path = _load()
