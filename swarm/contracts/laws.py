"""Law names, as a scenario gives them: a registered name or "package.module:function".
Resolving a name imports the module it points to, by name, so this contract depends on
no agent code; the laws themselves live in agents/ (docs/guides/writing-a-law.md).

Three places name a law, each with its signature, checked when a scenario is loaded:

    [law] follower  law(obs) -> u   registered: "bearing" (the paper's law, the default)
    [law] leader    law(obs) -> u   registered: "cc" (the CC planner and orbit hold, the default)
    [gains] law     law(g_i, g_j, lambda_ij, c1, c2) -> u   the older follower signature,
                    kept for existing scenarios; when it names anything but "bearing" it is
                    the follower law (and [law] follower must be left out)

`obs` is a swarm.contracts.observation.Observation; u in rad/s. A module is looked up on
sys.path, to which the scenario file's directory and $SWARM_LAW_PATH are appended.

A law must be a Python function (`def` or `lambda`, or a method bound to an object) whose
parameters take the arguments of its kind. Anything else that can be called is refused
when the scenario is loaded, naming the scenario field: a builtin (`os:system` takes one
argument, but a string, and would crash on the first tick), a class (`collections:OrderedDict`),
an object with `__call__`, a `functools.partial`: their signatures cannot be checked, or
do not mean what a law's does.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Callable, Iterable
from typing import Any

FollowerLaw = Callable[[float, float, float, float, float], float]  # [gains] law
Law = Callable[..., float]  # [law] follower / leader: law(obs) -> u

GAINS, FOLLOWER, LEADER = "gains", "follower", "leader"  # where a law is named: its kind
# Registered names -> "module:function", per kind.
LAW_NAMES: dict[str, str] = {"bearing": "swarm.agents.laws:bearing_law"}
REGISTRY: dict[str, dict[str, str]] = {
    GAINS: LAW_NAMES,
    FOLLOWER: {"bearing": "swarm.agents.laws:bearing"},
    LEADER: {"cc": "swarm.agents.leader:cc_law"},
}
DEFAULT = {FOLLOWER: "bearing", LEADER: "cc", GAINS: "bearing"}
MAX_LAW_PARAMS = 64  # entries of [law.params]

# A law named "module:function" is code: an agent imports it only when its own user said
# so (the launcher names its scenario's laws here; `swarm agent --trust-law`), never
# because a join reply names it.
ENV_TRUSTED_LAWS = "SWARM_TRUSTED_LAWS"
# Directories (os.pathsep-separated) appended to sys.path before a law module is imported:
# the launcher puts its scenario's directory here for its agents.
ENV_LAW_PATH = "SWARM_LAW_PATH"


class LawError(ValueError):
    """A law name that does not resolve to a callable of the right signature."""


def trusted_laws(extra: tuple[str, ...] | list[str] = ()) -> set[str]:
    """Laws this process may import: $SWARM_TRUSTED_LAWS (comma-separated) and `extra`."""
    env = os.environ.get(ENV_TRUSTED_LAWS, "")
    return {n.strip() for n in env.split(",") if n.strip()} | set(extra)


def with_trusted_laws(names: Any) -> str:
    """$SWARM_TRUSTED_LAWS for a child process: `names` and what this process trusts."""
    return ",".join(dict.fromkeys([*names, *sorted(trusted_laws())]))


def law_dirs(extra: Iterable = ()) -> list[str]:
    """Directories searched for law modules besides sys.path: `extra`, then $SWARM_LAW_PATH."""
    env = os.environ.get(ENV_LAW_PATH, "")
    return list(dict.fromkeys([*(str(d) for d in extra), *(d for d in env.split(os.pathsep) if d)]))


def with_law_path(dirs: Iterable) -> str:
    """$SWARM_LAW_PATH for a child process: `dirs` and what this process searches."""
    return os.pathsep.join(law_dirs(dirs))


def is_registered(name: str) -> bool:
    return any(name in names for names in REGISTRY.values())


def check_trusted(name: str, trusted: set[str]) -> None:
    """LawError unless `name` is registered (built in) or trusted by this process's user."""
    if is_registered(name) or name in trusted:
        return
    raise LawError(
        f"the world asks for law {name!r}, which this agent was not told to trust "
        f"(a law is code it would import): start it with --trust-law {name} or set "
        f"{ENV_TRUSTED_LAWS}={name}"
    )


def follower_law_name(gains_law: str, follower: str) -> tuple[str, str]:
    """(kind, name) of the law a follower runs: [gains] law when it names anything but the
    default, else [law] follower."""
    if gains_law != DEFAULT[GAINS]:
        return GAINS, gains_law
    return FOLLOWER, follower


def _what(kind: str) -> str:
    return "leader law" if kind == LEADER else "follower law"


def resolve_law(name: str, kind: str = GAINS, dirs: Iterable = ()) -> Law:
    """Return the law registered as `name` for `kind`, or import `module:function` (with
    `dirs` and $SWARM_LAW_PATH appended to sys.path first)."""
    names = REGISTRY[kind]
    target = names.get(name, name)
    if ":" not in target:
        raise LawError(f"unknown {_what(kind)} {name!r}: use one of {sorted(names)} or 'module:function'")
    mod_name, _, fn_name = target.partition(":")
    for d in law_dirs(dirs):
        if d not in sys.path:
            sys.path.append(d)  # appended: a scenario's directory cannot shadow installed modules
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as e:
        raise LawError(f"{_what(kind)} {name!r}: cannot import module {mod_name!r}: {e}") from None
    fn = getattr(mod, fn_name, None)
    if not callable(fn):
        raise LawError(f"{_what(kind)} {name!r}: module {mod_name!r} has no function {fn_name!r}")
    return fn


def _binds(fn: Any, *args: Any) -> bool:
    try:
        inspect.signature(fn).bind(*args)
    except (TypeError, ValueError):  # ValueError: no signature to check
        return False
    return True


def _is_python_function(fn: Any) -> bool:
    """A `def` or `lambda` (also one bound to an object): code whose signature is its own."""
    return inspect.isfunction(fn) or (inspect.ismethod(fn) and inspect.isfunction(fn.__func__))


def _kind_of(fn: Any) -> str:
    if inspect.isclass(fn):
        return "a class"
    if inspect.isbuiltin(fn) or inspect.ismethoddescriptor(fn) or type(fn).__name__ == "method-wrapper":
        return "a builtin"
    return f"a {type(fn).__name__} object"


def check_law(name: str, kind: str = GAINS, dirs: Iterable = ()) -> Law:
    """Resolve `name` and check that it is a Python function taking the arguments its kind
    documents."""
    law = resolve_law(name, kind, dirs)
    if not _is_python_function(law):
        raise LawError(
            f"{_what(kind)} {name!r} is {_kind_of(law)}, not a Python function (a law is a "
            "`def` taking "
            + ("(g_i, g_j, lambda_ij, c1, c2)" if kind == GAINS else "obs")
            + ", see docs/guides/writing-a-law.md)"
        )
    if kind == GAINS:
        if not _binds(law, 0.0, 0.0, 0.0, 1.0, 1.0):
            hint = "; a law of one argument (obs) goes in [law] follower" if _binds(law, None) else ""
            raise LawError(f"follower law {name!r} does not take (g_i, g_j, lambda_ij, c1, c2){hint}")
    elif not _binds(law, None):
        hint = (
            "; a (g_i, g_j, lambda_ij, c1, c2) law goes in [gains] law"
            if kind == FOLLOWER and _binds(law, 0.0, 0.0, 0.0, 1.0, 1.0)
            else ""
        )
        raise LawError(
            f"{_what(kind)} {name!r} does not take one argument (obs: an Observation, "
            f"see docs/guides/writing-a-law.md){hint}"
        )
    return law
