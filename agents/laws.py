"""Follower guidance laws, looked up by name.

A follower law is a pure function of the follower's own measurements:

    law(g_i, g_j, lambda_ij, c1, c2) -> u_i

    g_i        own heading (rad)
    g_j        heading of the out-neighbour j (rad)
    lambda_ij  line-of-sight angle from i to j, world frame (rad)
    c1, c2     the scenario's [gains]
    returns    turn rate u_i (rad/s); the agent saturates it at its max_turn_rate

No range and no target position enter a follower law. A scenario names its law in
`[gains] law = "bearing"` (the paper's law, the default) or `"package.module:function"`
for a law of your own with the signature above.
"""

from __future__ import annotations

import importlib
import math
from typing import Callable

FollowerLaw = Callable[[float, float, float, float, float], float]


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def bearing_law(g_i: float, g_j: float, lambda_ij: float, c1: float, c2: float) -> float:
    """The paper's law (Theorem 1): u_i = C1 wrap(g_j - g_i) + C2 sin(lambda_ij - g_i)."""
    return c1 * _wrap(g_j - g_i) + c2 * math.sin(lambda_ij - g_i)


LAWS: dict[str, FollowerLaw] = {"bearing": bearing_law}


class LawError(ValueError):
    """A law name that does not resolve to a callable."""


def resolve_law(name: str) -> FollowerLaw:
    """Return the law registered as `name`, or import `module:function`."""
    if name in LAWS:
        return LAWS[name]
    if ":" not in name:
        raise LawError(f"unknown follower law {name!r}: use one of {sorted(LAWS)} or 'module:function'")
    mod_name, _, fn_name = name.partition(":")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as e:
        raise LawError(f"follower law {name!r}: cannot import module {mod_name!r}: {e}") from None
    fn = getattr(mod, fn_name, None)
    if not callable(fn):
        raise LawError(f"follower law {name!r}: module {mod_name!r} has no function {fn_name!r}")
    return fn


def check_law(name: str) -> FollowerLaw:
    """Resolve `name` and check that it takes the five documented arguments."""
    import inspect

    law = resolve_law(name)
    try:
        inspect.signature(law).bind(0.0, 0.0, 0.0, 1.0, 1.0)
    except TypeError:
        raise LawError(f"follower law {name!r} does not take (g_i, g_j, lambda_ij, c1, c2)") from None
    except ValueError:
        pass  # builtins without a signature: trust them
    return law


def make_follower_law(name: str, c1: float, c2: float) -> Callable[[float, float, float], float]:
    """Check the gains once and return u(g_i, g_j, lambda_ij) with them bound."""
    if not (math.isfinite(c1) and math.isfinite(c2)):
        raise LawError(f"gains must be finite, got c1={c1}, c2={c2}")
    law = resolve_law(name)

    def u(g_i: float, g_j: float, lambda_ij: float) -> float:
        return float(law(g_i, g_j, lambda_ij, c1, c2))

    return u
