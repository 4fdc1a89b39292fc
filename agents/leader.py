"""Leader guidance: a circle-circle (CC) path onto a circular orbit, then orbit hold;
`cc_law` is both as a leader law on an Observation ("cc", the default leader law).

The leader is a unicycle  x' = v cos g,  y' = v sin g,  g' = u  (speed v in m/s,
turn rate u in rad/s, heading g in rad, counter-clockwise positive).  It reaches the
circular orbit of radius R (m) around a target, flown in direction s = +1 (ccw) or
s = -1 (cw), along the two tangent arcs of :func:`swarm.agents.cc_plan.plan_cc` (Lemma 1 of
Rao 2024), and then holds that orbit with :func:`on_orbit_command`, here.  `cc_law` plans
the path on its first call and keeps it in `obs.state`.

Pure functions on plain floats, standard library only: no numpy, so that a leader
process is as light as a follower's; no I/O, no middleware. The orbit hold and the arcs'
turn rates (`orbit_hold`, `arc_rate`) are written over the operations of agents/ops.py:
the batch brains (agents/batch_leader.py) run the same code on arrays of leaders.
"""

from __future__ import annotations

import math

from swarm.agents.cc_plan import check_inputs, plan_cc
from swarm.agents.ops import SCALAR, Num, Ops
from swarm.contracts.observation import Observation
from swarm.contracts.vocabulary import Phase

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
    u = orbit_hold(x, y, heading, v, radius, s)
    if max_turn_rate is not None:
        u = max(-max_turn_rate, min(max_turn_rate, u))
    return u


def orbit_hold(x: Num, y: Num, heading: Num, v: Num, radius: Num, s: Num, *, ops: Ops = SCALAR) -> Num:
    """on_orbit_command's turn rate before saturation, inputs already checked (s: +1 / -1).

    On floats; with ops=swarm.agents.batch_maths.ARRAY, on arrays of leaders (the batch
    brains): the same operations in the same order, so the same bits."""
    r = ops.hypot(x, y)
    theta = ops.atan2(y, x)
    e = (r - radius) / radius
    g_d = theta + s * (0.5 * math.pi + ops.atan(K_RADIAL * e))
    err = ops.wrap(g_d - heading)
    w0 = v / radius
    hold = (abs(e) <= _HOLD_DEADBAND) & (abs(err) <= _HOLD_DEADBAND)
    return ops.where(hold, s * w0, s * w0 + K_HEADING * w0 * err)


def _overlap(a: float, b: float, lo: Num | float, hi: Num | float, ops: Ops) -> Num:
    return ops.maximum(0.0, ops.minimum(b, hi) - ops.maximum(a, lo))


def arc_rate(a: float, dt: float, t1: Num, t2: Num, u1: Num, u2: Num, u_orbit: Num, *, ops: Ops = SCALAR) -> Num:
    """The CC path's turn rate averaged over the tick [a, a + dt) of path time (a < t1 + t2:
    the path has not ended): arc 1 (u1) until t1, arc 2 (u2) until t1 + t2, the orbit's
    u_orbit after. The tick on which an arc ends gets the time-weighted average: the switch
    between arcs rarely falls on a tick. On floats, or on arrays of leaders with
    ops=swarm.agents.batch_maths.ARRAY (the same bits)."""
    b = a + dt
    t12 = t1 + t2
    return (
        u1 * _overlap(a, b, 0.0, t1, ops)
        + u2 * _overlap(a, b, t1, t12, ops)
        + u_orbit * _overlap(a, b, t12, math.inf, ops)
    ) / dt


def leader_phase(a: float, t1: float, t2: float) -> Phase:
    """The phase of a leader at path time a on a CC path of arcs t1, t2 (s)."""
    if a >= t1 + t2:
        return Phase.ORBIT
    return Phase.ARC1 if a < t1 else Phase.ARC2


def cc_law(obs: Observation) -> float:
    """The built-in leader law ("cc"): the CC path planned from the first observation, flown
    arc by arc, then orbit hold (rad/s, before the agent's own saturation).

    obs.state keeps "cc_path" (an swarm.agents.cc_plan.CCPath), "path_tick" (the tick it was
    planned at) and "phase" ("arc1" | "arc2" | "orbit", the phase the agent reports). The
    tick on which an arc ends gets the time-weighted average of the turn rates over it:
    the switch between arcs rarely falls on a tick.
    """
    st = obs.state
    target, radius = obs.target, obs.orbit_radius
    if target is None or radius is None:
        raise ValueError("the 'cc' leader law needs the target and an orbit radius (a leader's observation)")
    px, py = -target[0], -target[1]  # own position relative to the target
    sign = obs.direction
    p = st.get("cc_path")
    if p is None:
        p = st["cc_path"] = plan_cc(px, py, obs.heading, obs.speed, radius, sign, obs.max_turn_rate)
        st["path_tick"] = obs.tick
    a = (obs.tick - st["path_tick"]) * obs.dt
    phase = st["phase"] = leader_phase(a, p.t1, p.t2)
    if phase is Phase.ORBIT:
        return on_orbit_command(px, py, obs.heading, obs.speed, radius, sign, obs.max_turn_rate)
    return arc_rate(a, obs.dt, p.t1, p.t2, p.u1, p.u2, sign * obs.speed / radius)
