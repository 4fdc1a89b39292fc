"""The candidate grid of the circle-circle (CC) planner (agents/cc_plan.py).

`best_cc` evaluates every candidate of a grid of entry angles and arc radii (Lemma 1,
in the form agents/cc_plan.py's docstring gives) in one plain-Python loop and keeps the
shortest feasible path of each entry angle; `linspace` and `geomspace` make the grids,
value for value as numpy does; `snap` drops an arc angle that is a rounding of 0. The
numerical guards of the search (tolerances, nudges) are here, with the loop they guard.
Pure functions on plain floats, standard library only (no numpy: a leader process is as
light as a follower's).
"""

from __future__ import annotations

import math
from typing import Any

from swarm.contracts.orbits import TAU

D_EPS = 1e-12  # alpha == beta (D ~ 0): no CC path through the Lemma 1 hyperbola
_ANGLE_SNAP = 1e-10  # an arc angle within this of 2 pi is a rounding of 0 (rad) ...
_LENGTH_SNAP = 1e-10  # ... if the arc length dropped is below this times the scene size
_MIN_GAP = 1e-6  # |r_A + r_B| below this times max(|r_A|, |r_B|, |a|, R): near-coincident
_TANGENCY_TOL = 1e-9  # relative residual of |o_A - o_B| = |r_A + r_B| accepted
_BOUNDARY_NUDGE = 1e-9  # radii placed exactly on r_min are pushed out by this fraction


def snap(d: float, r: float, scene: float) -> bool:
    """True when an arc angle d (rad) of radius r (m) just short of 2 pi is a rounded 0.

    Dropping the gap 2 pi - d moves the end point by about |r| (2 pi - d) (m) and turns
    the end heading by 2 pi - d (rad); both must be negligible for the scene size (m).
    (Inlined in :func:`best_cc`'s candidate loop; keep the two in step.)
    """
    gap = TAU - d
    return gap < _ANGLE_SNAP and abs(r) * gap <= _LENGTH_SNAP * scene


def linspace(start: float, stop: float, num: int) -> list[float]:
    """numpy.linspace(start, stop, num) for num >= 2 (endpoint included), value for value.

    numpy computes start + i * step with step = (stop - start) / (num - 1) (or, when the
    step underflows to 0, start + (i / (num - 1)) (stop - start)), then sets the last
    value to stop exactly; so does this.
    """
    div = num - 1
    delta = stop - start
    step = delta / div
    if step == 0.0:  # numpy's branch for denormal steps (numpy gh-5437)
        out = [i / div * delta + start for i in range(num)]
    else:
        out = [i * step + start for i in range(num)]
    out[-1] = stop
    return out


def geomspace(start: float, stop: float, num: int) -> list[float]:
    """numpy.geomspace(start, stop, num) for 0 < start, stop and num >= 2.

    numpy takes 10 ** linspace(log10(start), log10(stop), num) and then sets both ends
    exactly to start and stop; so does this.  Inner values can differ from numpy's in the
    last bits where numpy uses its own SIMD log10 / power (AVX-512 builds): harmless, the
    grid only seeds the search.
    """
    out = [10.0**e for e in linspace(math.log10(start), math.log10(stop), num)]
    out[0] = start
    out[-1] = stop
    return out


def best_cc(
    px: Any,
    py: Any,
    alpha: Any,
    radius: Any,
    s: Any,
    r_min: Any,
    r_cap: Any,
    phis: Any,
    mags: Any,
    n_best: Any = 1,
    n_ring: Any = 0,
) -> Any:
    """Evaluate CC candidates on a grid; return a list of (length, r_a, r_b, phi) or None.

    The list holds the shortest candidate of each of the n_best best entry angles, best
    first; with n_best > 1 only local minima over the equally spaced first n_ring angles
    (taken as a ring) compete, so the starts for refinement lie in different basins.

    phis: entry angles (rad); mags: |r_A| values (m), used with both signs.  Per entry
    angle, the candidates are, in this order (ties go to the first): r_A = +mags, -mags,
    +-r_min (nudged out), then the r_A giving r_B = s R (arc 2 on the orbit itself) and
    r_B = +-r_min.  The shortest feasible candidate of each entry angle counts; an
    infeasible one (degenerate, out of [r_min, r_cap], not tangent) is skipped.

    Plain Python, one candidate at a time (the hot loop of plan_cc: everything inlined).
    It is the numpy planner it replaced (`_best_cc` in tests/support/cc_reference.py) operation for operation:
    divisions by zero, which numpy turned into inf / nan, are guarded instead (such
    candidates are infeasible either way); math.hypot can differ from numpy's hypot in
    the last bit, which matters only exactly at the tangency tolerance.
    """
    cos, sin, hypot, atan2 = math.cos, math.sin, math.hypot, math.atan2
    inf = math.inf
    ca, sa = cos(alpha), sin(alpha)
    quarter = s * (0.5 * math.pi)
    sr = s * radius
    edge = r_min * (1.0 + _BOUNDARY_NUDGE)
    neg_edge = -edge
    grid = [*mags, *[-m for m in mags], edge, neg_edge]
    j_orbit = len(grid)  # index of the r_B = s R candidate
    angle_snap, length_snap, min_gap, tangency = _ANGLE_SNAP, _LENGTH_SNAP, _MIN_GAP, _TANGENCY_TOL

    per_phi, best_ra, best_rb = [], [], []
    for phi in phis:
        bx, by = radius * cos(phi), radius * sin(phi)
        beta = phi + quarter
        cb, sb = cos(beta), sin(beta)
        ax, ay = px - bx, py - by
        pa = ax * sa - ay * ca
        pb = ax * sb - ay * cb
        h = sin(0.5 * (alpha - beta))
        d = 2.0 * (h * h)
        if not d > D_EPS:  # alpha == beta: no candidate at this entry angle
            per_phi.append(inf)
            best_ra.append(0.0)
            best_rb.append(0.0)
            continue
        half_a2 = 0.5 * (ax * ax + ay * ay)
        norm_a = math.sqrt(2.0 * half_a2)
        scene = max(norm_a, radius)  # also the size floor of each candidate's scale
        snap_len = length_snap * scene
        # r_A giving a chosen r_B: r_A = (|a|^2/2 + r_B Pb) / (r_B D - Pa); nan (rejected
        # below) where the denominator vanishes
        ras = grid.copy()
        for rbt in (sr, edge, neg_edge):
            den0 = rbt * d - pa
            ras.append((half_a2 + rbt * pb) / den0 if den0 != 0.0 else math.nan)

        best, bra, brb = inf, 0.0, 0.0
        j = -1
        for ra in ras:
            j += 1
            den = ra * d - pb
            if not abs(den) > 1e-300:
                continue
            # exact r_B = s R for the orbit candidate (o_B is then exactly the target)
            rb = sr if j == j_orbit else (half_a2 + ra * pa) / den
            ara = abs(ra)
            arb = abs(rb)
            # the bounds also reject inf / nan (r_cap is finite)
            if not (r_min <= ara <= r_cap and r_min <= arb <= r_cap):
                continue
            ssum = ra + rb
            scale = ara if ara > scene else scene  # max(|r_A|, |r_B|, |a|, R)
            if arb > scale:
                scale = arb
            if not abs(ssum) > min_gap * scale:
                continue
            dx = ax + ra * sa + rb * sb  # o_A - o_B
            dy = ay - ra * ca - rb * cb
            if not abs(hypot(dx, dy) - abs(ssum)) <= tangency * scale:
                continue
            gt = atan2(dx / ssum, -(dy / ssum))
            # arc senses -sign(r_A), sign(r_B): r_A, r_B are nonzero here (|r| >= r_min)
            d1 = (alpha - gt if ra > 0.0 else gt - alpha) % TAU
            d2 = (beta - gt if rb > 0.0 else gt - beta) % TAU
            gap = TAU - d1
            if gap < angle_snap and ara * gap <= snap_len:
                d1 = 0.0
            gap = TAU - d2
            if gap < angle_snap and arb * gap <= snap_len:
                d2 = 0.0
            length = ara * d1 + arb * d2
            if length < best:
                best, bra, brb = length, ra, rb
        per_phi.append(best)
        best_ra.append(bra)
        best_rb.append(brb)

    # the n_best shortest entry angles among the local minima over the circular grid (the
    # first n_ring angles) and the extra angles; a stable sort keeps ties in grid order
    eligible = [length < inf for length in per_phi]
    if n_best > 1 and n_ring >= 3:
        for i in range(n_ring):
            if eligible[i] and not (
                per_phi[i] <= per_phi[i - 1 if i else n_ring - 1] and per_phi[i] <= per_phi[(i + 1) % n_ring]
            ):
                eligible[i] = False
    order = sorted((i for i, ok in enumerate(eligible) if ok), key=per_phi.__getitem__)[:n_best]
    if not order:
        return None
    return [(per_phi[i], best_ra[i], best_rb[i], phis[i]) for i in order]
