"""Bad input to swarm.env: a one-line error naming the argument, or the documented
saturation (docs/guides/learning.md#bad-input).

- `EnvError` (a `swarm.UsageError`, so a ValueError): a value out of its domain (a
  non-finite duration, a negative k_nearest, a NaN action, an unknown agent, a wrong shape);
- `EnvTypeError` (also a TypeError): a value of the wrong type (a string or None for an
  action, a float k_nearest, a seed that is not an int, actions that are not a dict).

Actions are turn rates (rad/s). A finite one beyond the agent's limit is saturated at it
(`action_limit`: its max_turn_rate, or pi / dt for an agent without one: half a turn per
tick, past which a turn rate aliases), so an action of 1e308 is a hard turn, never a poisoned
episode; a NaN or an infinite one is an error naming the agent. Only numpy is needed here.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from swarm.contracts.errors import UsageError
from swarm.contracts.scenario_tables import MAX_AGENT_TICKS, MAX_SEED, RECORDING_LIMIT


class EnvError(UsageError):
    """A bad argument to swarm.env (a ValueError); the message names it."""


class EnvTypeError(EnvError, TypeError):
    """An argument of the wrong type (a TypeError and a ValueError); the message names it."""


def _kind(value: Any) -> str:
    return "None" if value is None else type(value).__name__


def real(value: Any, what: str) -> float:
    """`value` as a float if it is a real number (an int, a float, a numpy one; not a bool,
    a string, None or a complex), else EnvTypeError naming `what`."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise EnvTypeError(f"{what} must be a real number, not {_kind(value)} {value!r}")
    return float(value)


def duration_ticks(duration: Any, dt: float, agents: int) -> int | None:
    """The ticks of an episode of `duration` seconds (None: the scenario's own)."""
    if duration is None:
        return None
    d = real(duration, "duration")
    if not math.isfinite(d) or d <= 0.0:
        raise EnvError(f"duration must be a finite number of seconds > 0, not {d!r}")
    ticks = int(round(d / dt))
    if ticks == 0:
        raise EnvError(f"duration {d:g} s is shorter than one tick (run.dt = {dt:g} s)")
    if ticks * agents > MAX_AGENT_TICKS:
        raise EnvError(
            f"duration {d:g} s is {ticks} ticks x {agents} agents, more than the recording limit of "
            f"{RECORDING_LIMIT}; use a shorter duration"
        )
    return ticks


def run_dt(dt: Any) -> float:
    """A scenario's run.dt (a Scenario built without validation could hold anything)."""
    d = real(dt, "scenario run.dt")
    if not math.isfinite(d) or d <= 0.0:
        raise EnvError(f"scenario run.dt must be a finite number of seconds > 0, not {d!r}")
    return d


def k_nearest(k: Any) -> int:
    """Contacts in an observation: an int >= 0 (0: the out-neighbour block only)."""
    if isinstance(k, bool | np.bool_) or not isinstance(k, numbers.Integral):
        raise EnvTypeError(f"k_nearest must be an int >= 0, not {_kind(k)} {k!r}")
    if k < 0:
        raise EnvError(f"k_nearest must be an int >= 0, not {k}")
    return int(k)


def seed(value: Any, what: str = "seed") -> int | None:
    """A seed: None, or an int in 0 .. 2**63 - 1 (a scenario's run.seed's range)."""
    if value is None:
        return None
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise EnvTypeError(f"{what} must be an int or None, not {_kind(value)} {value!r}")
    v = int(value)
    if not 0 <= v <= MAX_SEED:
        raise EnvError(f"{what} must be in 0 .. 2**63 - 1, not {v}")
    return v


def jitter(value: Any, what: str) -> float:
    """A start jitter: a finite number >= 0."""
    v = real(value, what)
    if not math.isfinite(v) or v < 0.0:
        raise EnvError(f"{what} must be a finite number >= 0, not {v!r}")
    return v


def action_limit(max_turn_rate: float | None, dt: float) -> float:
    """The largest turn rate an action gives (rad/s): the agent's max_turn_rate, or pi / dt
    for an agent without one (half a turn per tick: beyond it a turn rate aliases)."""
    return max_turn_rate if max_turn_rate is not None else math.pi / dt


def action(name: str, value: Any, limit: float) -> float:
    """One agent's action as a turn rate saturated at `limit`: a real number, or an array
    (list, tuple) of exactly one; EnvTypeError / EnvError naming `actions[name]` else."""
    what = f"actions[{name!r}]"
    if isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_):
        u = float(value)
    else:
        if value is None or isinstance(value, str | bytes | numbers.Complex | bool | np.bool_):
            raise EnvTypeError(f"{what} must be a turn rate (a real number or an array of one), not {_kind(value)}")
        try:
            a = np.asarray(value)
        except Exception as err:  # ragged lists and the like
            raise EnvTypeError(f"{what} must be a turn rate (a real number or an array of one): {err}") from None
        if a.dtype.kind not in "iuf":
            raise EnvTypeError(f"{what} must hold a real number, not an array of {a.dtype}")
        if a.size != 1 or a.ndim > 1:
            raise EnvError(f"{what} must be a number or an array of one, not an array of shape {a.shape}")
        u = float(a.reshape(-1)[0])
    if not math.isfinite(u):
        raise EnvError(f"{what} is {u}: a turn rate must be finite")
    return u if -limit <= u <= limit else max(-limit, min(limit, u))


def actions_dict(actions: Any) -> dict:
    """The actions argument of SwarmEnv.step: a dict (any Mapping) of agent name -> action."""
    if not hasattr(actions, "keys") or not hasattr(actions, "get"):
        raise EnvTypeError(f"actions must be a dict of agent name -> turn rate, not {_kind(actions)}")
    return dict(actions)


def unknown_agents(names: Any, possible: Sequence[str]) -> None:
    """EnvError naming the first action key that is no agent of the environment."""
    known = set(possible)
    for n in names:
        if n not in known:
            shown = ", ".join(possible[:6]) + (", ..." if len(possible) > 6 else "")
            raise EnvError(f"actions: unknown agent {n!r} (this environment's agents: {shown})")


def actions_array(actions: Any, shape: tuple[int, int], name_of: Any) -> np.ndarray:
    """The actions argument of VectorSwarmEnv.step: a real (B, A) array (or (B, A, 1)),
    finite; name_of(b, a) names an entry in the error."""
    if actions is None or isinstance(actions, str | bytes | numbers.Number | dict):
        raise EnvTypeError(f"actions must be a real array of shape {shape} (swarms x agents), not {_kind(actions)}")
    try:
        a = np.asarray(actions)
    except Exception as err:
        raise EnvTypeError(f"actions must be a real array of shape {shape} (swarms x agents): {err}") from None
    if a.dtype.kind not in "iuf":
        raise EnvTypeError(f"actions must be a real array of shape {shape}, not an array of {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.shape != shape:
        raise EnvError(f"actions must have shape {shape} (swarms x agents), not {a.shape}")
    a = a.astype(float, copy=False)
    bad = ~np.isfinite(a)
    if bad.any():
        b, k = (int(v) for v in np.argwhere(bad)[0])
        raise EnvError(f"actions[{b}, {k}] ({name_of(b, k)}) is {a[b, k]}: a turn rate must be finite")
    return a
