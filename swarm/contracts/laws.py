"""Follower-law names, as a scenario's `[gains] law` gives them: a registered name (the
paper's law is "bearing") or "package.module:function". Resolving a name imports the
module it points to, by name, so this contract depends on no agent code; the laws
themselves live in agents/laws.py.

A follower law takes (g_i, g_j, lambda_ij, c1, c2) in rad and the gains, and returns u_i
in rad/s (see agents/laws.py).
"""

from __future__ import annotations

import importlib
import inspect
import os
from typing import Callable

FollowerLaw = Callable[[float, float, float, float, float], float]

# Registered names -> "module:function".
LAW_NAMES: dict[str, str] = {"bearing": "agents.laws:bearing_law"}


# A law named "module:function" is code: an agent imports it only when its own user said
# so (the launcher names its scenario's law here; `swarm agent --trust-law`), never
# because a join reply names it.
ENV_TRUSTED_LAWS = "SWARM_TRUSTED_LAWS"


class LawError(ValueError):
    """A law name that does not resolve to a callable."""


def trusted_laws(extra: tuple[str, ...] | list[str] = ()) -> set[str]:
    """Laws this process may import: $SWARM_TRUSTED_LAWS (comma-separated) and `extra`."""
    env = os.environ.get(ENV_TRUSTED_LAWS, "")
    return {n.strip() for n in env.split(",") if n.strip()} | set(extra)


def with_trusted_laws(names) -> str:
    """$SWARM_TRUSTED_LAWS for a child process: `names` and what this process trusts."""
    return ",".join(dict.fromkeys([*names, *sorted(trusted_laws())]))


def check_trusted(name: str, trusted: set[str]) -> None:
    """LawError unless `name` is registered (built in) or trusted by this process's user."""
    if name in LAW_NAMES or name in trusted:
        return
    raise LawError(f"the world asks for follower law {name!r}, which this agent was not told to trust "
                   f"(a law is code it would import): start it with --trust-law {name} or set "
                   f"{ENV_TRUSTED_LAWS}={name}")


def resolve_law(name: str) -> FollowerLaw:
    """Return the law registered as `name`, or import `module:function`."""
    target = LAW_NAMES.get(name, name)
    if ":" not in target:
        raise LawError(f"unknown follower law {name!r}: use one of {sorted(LAW_NAMES)} or 'module:function'")
    mod_name, _, fn_name = target.partition(":")
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
    law = resolve_law(name)
    try:
        inspect.signature(law).bind(0.0, 0.0, 0.0, 1.0, 1.0)
    except TypeError:
        raise LawError(f"follower law {name!r} does not take (g_i, g_j, lambda_ij, c1, c2)") from None
    except ValueError:
        pass  # builtins without a signature: trust them
    return law
