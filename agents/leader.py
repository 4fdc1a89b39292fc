"""Leader guidance: a circle-circle (CC) path onto a circular orbit, then orbit hold;
`cc_law` is both as a leader law on an Observation ("cc", the default leader law).

The leader is a unicycle  x' = v cos g,  y' = v sin g,  g' = u  (speed v in m/s,
turn rate u in rad/s, heading g in rad, counter-clockwise positive).  It reaches the
circular orbit of radius R (m) around a target, flown in direction s = +1 (ccw) or
s = -1 (cw), along the two tangent arcs of :func:`swarm.agents.cc_plan.plan_cc` (Lemma 1 of
Rao 2024), and then holds that orbit with :func:`on_orbit_command`, here.  `cc_law` plans
the path on its first call and keeps it in `obs.state`.

Pure functions on plain floats, standard library only: no numpy, so that a leader
process is as light as a follower's; no I/O, no middleware.
"""

from __future__ import annotations

import math

from swarm.agents.cc_plan import check_inputs, plan_cc
from swarm.contracts.observation import Observation
from swarm.contracts.orbits import wrap

#: Orbit-hold gains (dimensionless): desired heading leans atan(K_RADIAL (r - R)/R)
#: towards the orbit; heading error feedback gain is K_HEADING * v / R (1/s).  The
#: linearised radial error obeys e'' + K_H w0 e' + w0^2 (1 + K_H K_R) e = 0 with
#: w0 = v / R, i.e. poles at -2 w0 and -3 w0 for (K_R, K_H) = (1, 5): overdamped.
K_RADIAL = 1.0
K_HEADING = 5.0

_HOLD_DEADBAND = 1e-12  # on_orbit_command: errors below this are rounding, not drift


def on_orbit_command(
    x: float, y: float, heading: float, v: float, radius: float, direction: int, max_turn_rate: float | None = None
) -> float:
    """Orbit-hold turn rate (rad/s) for a leader near its orbit.

    x, y: position relative to the target (m); heading (rad); v (m/s); radius R (m);
    direction +1 ccw / -1 cw; max_turn_rate (rad/s) or None.

    u = s v / R + K_HEADING (v / R) wrap(g_d - g),
    g_d = theta + s (pi / 2 + atan(K_RADIAL (r - R) / R)),

    so the correction is zero on the orbit with tangent heading (errors below 1e-12 are
    treated as rounding and give exactly s v / R) and pulls radial / heading errors back
    without overshoot.  Saturated at +-max_turn_rate when given.
    """
    s = check_inputs(v, radius, direction, max_turn_rate)
    r = math.hypot(x, y)
    theta = math.atan2(y, x)
    e = (r - radius) / radius
    g_d = theta + s * (0.5 * math.pi + math.atan(K_RADIAL * e))
    err = wrap(g_d - heading)
    w0 = v / radius
    if abs(e) <= _HOLD_DEADBAND and abs(err) <= _HOLD_DEADBAND:
        u = s * w0
    else:
        u = s * w0 + K_HEADING * w0 * err
    if max_turn_rate is not None:
        u = max(-max_turn_rate, min(max_turn_rate, u))
    return u


def _overlap(a: float, b: float, lo: float, hi: float) -> float:
    return max(0.0, min(b, hi) - max(a, lo))


def cc_law(obs: Observation) -> float:
    """The built-in leader law ("cc"): the CC path planned from the first observation, flown
    arc by arc, then orbit hold (rad/s, before the agent's own saturation).

    obs.state keeps "cc_path" (an swarm.agents.cc_plan.CCPath), "path_tick" (the tick it was
    planned at) and "phase" ("arc1" | "arc2" | "orbit", the phase the agent reports). The
    tick on which an arc ends gets the time-weighted average of the turn rates over it:
    the switch between arcs rarely falls on a tick.
    """
    st = obs.state
    px, py = -obs.target[0], -obs.target[1]  # own position relative to the target
    sign = obs.direction
    p = st.get("cc_path")
    if p is None:
        p = st["cc_path"] = plan_cc(px, py, obs.heading, obs.speed, obs.orbit_radius, sign, obs.max_turn_rate)
        st["path_tick"] = obs.tick
    a = (obs.tick - st["path_tick"]) * obs.dt
    b = a + obs.dt
    t12 = p.t1 + p.t2
    if a >= t12:
        st["phase"] = "orbit"
        return on_orbit_command(px, py, obs.heading, obs.speed, obs.orbit_radius, sign, obs.max_turn_rate)
    u_orbit = sign * obs.speed / obs.orbit_radius
    st["phase"] = "arc1" if a < p.t1 else "arc2"
    return (
        p.u1 * _overlap(a, b, 0.0, p.t1) + p.u2 * _overlap(a, b, p.t1, t12) + u_orbit * _overlap(a, b, t12, math.inf)
    ) / obs.dt
