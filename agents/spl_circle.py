"""A second circumnavigation law, from the literature: circular motion about the target
in the splay state (every agent on one circle, evenly spaced), as a leader law.

Source: R. Sepulchre, D. A. Paley, N. E. Leonard, "Stabilization of planar collective
motion: all-to-all communication", IEEE Transactions on Automatic Control 52(5),
811-824, 2007: the circular control law that drives each particle onto a circle of
radius 1/|omega0|, with the circle's centre fixed (a beacon; here, the target) instead
of the group's centroid, plus the gradient of their phase potential U^{M,N}, whose
minimum is the splay state. The paper's particles fly at unit speed; below everything is
written for a speed v (m/s), and the Lyapunov argument is re-derived for it.

Model (complex notation, <a, b> = Re(conj(a) b)): r_k' = v e^{i theta_k}, theta_k' = u_k,
r~_k = r_k - c0 (position relative to the target c0, m). The law of agent k is

    u_k = omega0 (1 + kappa <r~_k, e^{i theta_k}>) - sum_{m=1..M} K <p_m, i e^{i m theta_k}>

    omega0 = s v / R              (rad/s; s = +1 ccw, -1 cw; R the agent's orbit_radius)
    p_m = (1 / (m N)) sum_j e^{i m theta_j}   (over the N agents: itself and every contact)
    <r~_k, e^{i theta_k}> = x~ cos theta_k + y~ sin theta_k
    <p_m, i e^{i m theta_k}> = -Re p_m sin(m theta_k) + Im p_m cos(m theta_k)

with kappa > 0 (1/m), K >= 0 (1/s) and M = floor(N / 2) harmonics: [law.params] kappa
(default 1 / R), k_phase (K, default |omega0| / 2) and harmonics (M).

Why it works. The centre of agent k's turning circle is c_k = r_k + (v / omega0) i e^{i theta_k};
c_k' = v e^{i theta_k} (1 - u_k / omega0). With U(theta) = sum_m K (N / 2) |p_m|^2
(dU/dtheta_k = sum_m K <p_m, i e^{i m theta_k}>, and sum_k dU/dtheta_k = 0) and
w_k = u_k - omega0, the function V = (kappa omega0^2 / v) (1/2) sum_k |c_k - c0|^2 + U has
V' = -sum_k w_k^2 <= 0 for the law above. Where V' = 0 every agent turns at omega0 with its
heading tangent to the circle about c0: an orbit of radius R = v / |omega0| about the target.
Where U is least (0), p_1 = ... = p_M = 0, which for M = floor(N / 2) holds only in the splay
state (Newton's identities on z_j = e^{i theta_j}, |z_j| = 1): the headings, hence the
agents' angles about the target, 2 pi / N apart. Other critical points of U are equilibria
too (the paper's Lyapunov functions prove its circular formations exponentially stable and
suggest, without proving, almost global convergence); from the shipped scenario's start the
run ends in the splay state.

Documented equilibrium (checked by tests/pure/test_spl_law.py through `swarm sim`): every agent
at distance R from the target, circling in direction s, neighbours 2 pi / N apart. It
needs every agent to sense every other (all-to-all, the paper's setting: no sensing range
or field of view), equal speeds and radii (one omega0), and the target (a leader law: in
this project only leaders know where the target is). scenarios/spl-splay.toml runs it.
"""

from __future__ import annotations

import math

from swarm.contracts.observation import Observation


def spl_circle(obs: Observation) -> float:
    """u_k (rad/s) of the circular control law with phase coupling (module docstring)."""
    radius = obs.orbit_radius
    if obs.target is None or radius is None:
        raise ValueError("swarm.agents.spl_circle:spl_circle needs the target: name it as a leader law ([law] leader)")
    w0 = obs.direction * obs.speed / radius
    kappa = obs.params.get("kappa", 1.0 / radius)
    k_phase = obs.params.get("k_phase", 0.5 * abs(w0))
    th = obs.heading
    x, y = -obs.target[0], -obs.target[1]  # r~_k: own position relative to the target
    u = w0 * (1.0 + kappa * (x * math.cos(th) + y * math.sin(th)))
    headings = [th] + [c.heading for c in obs.contacts]
    n = len(headings)
    for m in range(1, int(obs.params.get("harmonics", n // 2)) + 1):
        px = sum(math.cos(m * h) for h in headings) / (m * n)
        py = sum(math.sin(m * h) for h in headings) / (m * n)
        u -= k_phase * (py * math.cos(m * th) - px * math.sin(m * th))
    return u
