"""Laws defined outside the package, for the `module:function` lookup tests: follower laws
of the older signature (g_i, g_j, lambda_ij, c1, c2), then laws of the observation API."""

import math

CONSTANT_U = 0.3


def constant_law(g_i, g_j, lambda_ij, c1, c2):
    """Ignores every measurement: the follower flies a circle of radius v / CONSTANT_U."""
    return CONSTANT_U


def fast_law(g_i, g_j, lambda_ij, c1, c2):
    """A turn rate far above any agent's limit (to exercise saturation)."""
    return 100.0


def nan_law(g_i, g_j, lambda_ij, c1, c2):
    return float("nan")


def gains_law(g_i, g_j, lambda_ij, c1, c2):
    """Echo the gains and inputs so the binding order can be checked."""
    return 1000.0 * c1 + c2 + 0.001 * (g_i + 10 * g_j + 100 * lambda_ij)


NOT_A_FUNCTION = 3


# -- laws of the observation API: law(obs) -> u ------------------------------------------------

LEADER_RATE = 0.4


def orbit_rate_leader(obs):
    """A trivial leader law: turn at a fixed rate (obs.params["rate"], else LEADER_RATE), i.e.
    a circle of radius v / rate wherever it starts; counts its calls in obs.state."""
    obs.state["calls"] = obs.state.get("calls", 0) + 1
    return obs.params.get("rate", LEADER_RATE)


def stateful_follower(obs):
    """Steer like a pure-pursuit follower (towards the out-neighbour) with the gain
    obs.params["k"], loiter at c2 when there is none; remember every out-neighbour seen."""
    seen = obs.state.setdefault("seen", [])
    if obs.out is None:
        return obs.c2
    if obs.out.id not in seen:
        seen.append(obs.out.id)
    return obs.params.get("k", 1.0) * math.sin(obs.out.bearing - obs.heading)


def echo_obs(obs):
    """Returns 0.0 and keeps the last observation it was given in obs.state."""
    obs.state["obs"] = obs
    return 0.0


def two_arg_law(obs, extra):
    """The wrong signature for [law] follower / leader."""
    return 0.0
