"""Test-only reference: the numpy planner as it was before the port, kept to check the pure-Python port.

This is a frozen copy of agents/leader.py's circle-circle planner (`plan_cc` with its
helpers `_best_cc`, `_snap`, `_single_arc_phi`, `_orbit_path`, input checks and tuning
constants) as it stood when the planner was still vectorised with numpy, before the
port to plain Python that keeps leader processes numpy-free.  It is used only
by tests/process/test_leader.py to check that the port plans the same paths; nothing in the
runtime imports it.  Do not "fix" it: it is the yardstick, not a second implementation.
Only `CCPath` (the result record), `wrap` and `TAU` are shared with the live code.
"""

from __future__ import annotations

import math

import numpy as np

from swarm.agents.cc_plan import CCPath
from swarm.contracts.orbits import TAU, wrap

#: Without a turn-rate limit the smallest admissible arc radius is this fraction of R,
#: i.e. the planned turn rates stay below 10x the orbit's own turn rate v / R.
DEFAULT_MIN_RADIUS_FRACTION = 0.1

_D_EPS = 1e-12  # alpha == beta (D ~ 0): no CC path through the Lemma 1 hyperbola
_ON_ORBIT_TOL = 1e-9  # plan_cc: "already on the orbit" tolerance (relative radius / rad)
_ANGLE_SNAP = 1e-10  # an arc angle within this of 2 pi is a rounding of 0 (rad) ...
_LENGTH_SNAP = 1e-10  # ... if the arc length dropped is below this times the scene size
_MIN_GAP = 1e-6  # |r_A + r_B| below this times max(|r_A|, |r_B|, |a|, R): near-coincident
_TANGENCY_TOL = 1e-9  # relative residual of |o_A - o_B| = |r_A + r_B| accepted
_BOUNDARY_NUDGE = 1e-9  # radii placed exactly on r_min are pushed out by this fraction
_N_STARTS = 4  # plan_cc refines around this many of the best coarse entry angles


def _min_radius(v: float, radius: float, max_turn_rate: float | None) -> float:
    if max_turn_rate is None:
        return DEFAULT_MIN_RADIUS_FRACTION * radius
    return v / max_turn_rate


def _check_inputs(v: float, radius: float, direction: int, max_turn_rate: float | None) -> int:
    if not (v > 0.0 and math.isfinite(v)):
        raise ValueError(f"speed must be > 0, got {v!r}")
    if not (radius > 0.0 and math.isfinite(radius)):
        raise ValueError(f"orbit radius must be > 0, got {radius!r}")
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 (ccw) or -1 (cw), got {direction!r}")
    if max_turn_rate is not None and not max_turn_rate > 0.0:
        raise ValueError(f"max_turn_rate must be > 0 or None, got {max_turn_rate!r}")
    return int(direction)


def _snap(d, r, scene):
    """True where an arc angle d (rad) of radius r (m) just short of 2 pi is a rounded 0.

    Dropping the gap 2 pi - d moves the end point by about |r| (2 pi - d) (m) and turns
    the end heading by 2 pi - d (rad); both must be negligible for the scene size (m).
    """
    gap = TAU - d
    return (gap < _ANGLE_SNAP) & (np.abs(r) * gap <= _LENGTH_SNAP * scene)


def _best_cc(px, py, alpha, radius, s, r_min, r_cap, phis, mags, n_best=1, n_ring=0):
    """Evaluate CC candidates on a grid; return a list of (length, r_a, r_b, phi) or None.

    The list holds the shortest candidate of each of the n_best best entry angles, best
    first; with n_best > 1 only local minima over the equally spaced first n_ring angles
    (taken as a ring) compete, so the starts for refinement lie in different basins.

    phis: (P,) entry angles (rad); mags: (K,) |r_A| values (m), used with both signs.
    Per entry angle, boundary candidates are added: |r_A| = r_min, |r_B| = r_min and
    r_B = s R (arc 2 on the orbit itself).
    """
    phis = np.asarray(phis, dtype=float)[:, None]
    ca, sa = math.cos(alpha), math.sin(alpha)
    bx, by = radius * np.cos(phis), radius * np.sin(phis)
    beta = phis + s * (0.5 * math.pi)
    cb, sb = np.cos(beta), np.sin(beta)
    ax, ay = px - bx, py - by
    pa = ax * sa - ay * ca
    pb = ax * sb - ay * cb
    d = 2.0 * np.sin(0.5 * (alpha - beta)) ** 2
    half_a2 = 0.5 * (ax * ax + ay * ay)

    edge = r_min * (1.0 + _BOUNDARY_NUDGE)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # r_A giving a chosen r_B: r_A = (|a|^2/2 + r_B Pb) / (r_B D - Pa)
        rb_targets = np.array([s * radius, edge, -edge])[None, :]
        ra_special = (half_a2 + rb_targets * pb) / (rb_targets * d - pa)
        ra_grid = np.concatenate([mags, -mags, [edge, -edge]])[None, :]
        ra_grid = np.broadcast_to(ra_grid, (phis.shape[0], ra_grid.shape[1]))
        ra = np.concatenate([ra_grid, ra_special], axis=1)
        den = ra * d - pb
        rb = (half_a2 + ra * pa) / den
        # exact r_B = s R for the orbit candidate (o_B is then exactly the target)
        rb[:, -3] = s * radius

        oax, oay = ax + ra * sa, ay - ra * ca
        obx, oby = -rb * sb, rb * cb
        dx, dy = oax - obx, oay - oby
        ssum = ra + rb
        dist = np.hypot(dx, dy)
        scale = np.maximum.reduce([np.abs(ra), np.abs(rb), np.sqrt(2.0 * half_a2) + 0.0 * ra, np.full_like(ra, radius)])
        ok = (
            (d > _D_EPS)
            & np.isfinite(ra)
            & np.isfinite(rb)
            & (np.abs(den) > 1e-300)
            & (np.abs(ra) >= r_min)
            & (np.abs(rb) >= r_min)
            & (np.abs(ra) <= r_cap)
            & (np.abs(rb) <= r_cap)
            & (np.abs(ssum) > _MIN_GAP * scale)
            & (np.abs(dist - np.abs(ssum)) <= _TANGENCY_TOL * scale)
        )
        if not ok.any():
            return None
        nx, ny = dx / ssum, dy / ssum
        gt = np.arctan2(nx, -ny)
        d1 = np.mod(-np.sign(ra) * (gt - alpha), TAU)
        d2 = np.mod(np.sign(rb) * (beta - gt), TAU)
    scene = np.maximum(np.sqrt(2.0 * half_a2), radius)
    d1 = np.where(_snap(d1, ra, scene), 0.0, d1)
    d2 = np.where(_snap(d2, rb, scene), 0.0, d2)
    length = np.where(ok, np.abs(ra) * d1 + np.abs(rb) * d2, np.inf)
    # shortest candidate per entry angle; then the n_best shortest entry angles among the
    # local minima over the circular grid (the first n_ring angles) and the extra angles
    k = np.argmin(length, axis=1)
    rows = np.arange(length.shape[0])
    per_phi = length[rows, k]
    eligible = np.isfinite(per_phi)
    if n_best > 1 and n_ring >= 3:
        ring = per_phi[:n_ring]
        eligible[:n_ring] &= (ring <= np.roll(ring, 1)) & (ring <= np.roll(ring, -1))
    order = [i for i in np.argsort(np.where(eligible, per_phi, np.inf), kind="stable")[:n_best] if eligible[i]]
    if not order:
        return None
    return [(float(per_phi[i]), float(ra[i, k[i]]), float(rb[i, k[i]]), float(phis[i, 0])) for i in order]


def _single_arc_phi(px, py, alpha, radius, s):
    """Entry angle (rad) of the one-arc path: circle A tangent to the orbit itself, or None.

    Circle A through the start with heading alpha is tangent to the orbit (as circle B with
    r_B = s R) for r_A = (R^2 - |p|^2) / (2 (p . n - s R)), n = (sin alpha, -cos alpha).
    """
    nx, ny = math.sin(alpha), -math.cos(alpha)
    den = 2.0 * (px * nx + py * ny - s * radius)
    if abs(den) < 1e-12 * radius:
        return None
    ra = (radius * radius - px * px - py * py) / den
    ox, oy = px + ra * nx, py + ra * ny
    ssum = ra + s * radius
    if abs(ssum) < 1e-12 * radius:
        return None
    return math.atan2(s * oy / ssum, s * ox / ssum)


def _orbit_path(x, y, v, radius, s) -> CCPath:
    """Zero-length path for a leader already on the orbit (both arcs are the orbit)."""
    theta = math.atan2(y, x)
    entry = (radius * math.cos(theta), radius * math.sin(theta), wrap(theta + s * 0.5 * math.pi))
    return CCPath(
        r_a=-s * radius, r_b=s * radius, u1=s * v / radius, u2=s * v / radius, t1=0.0, t2=0.0, entry=entry, length=0.0
    )


def plan_cc(
    x: float,
    y: float,
    heading: float,
    v: float,
    radius: float,
    direction: int,
    max_turn_rate: float | None = None,
    *,
    n_entry: int = 72,
) -> CCPath:
    """Shortest circle-circle path (over a candidate grid) from a pose onto the orbit.

    x, y: leader position relative to the target (m); heading (rad); v: speed (m/s) > 0;
    radius: orbit radius R (m) > 0; direction: +1 ccw / -1 cw; max_turn_rate: turn-rate
    limit (rad/s) or None; n_entry: number of equally spaced entry angles phi tried.

    Both arc radii satisfy |r| >= r_min, r_min = v / max_turn_rate, or
    DEFAULT_MIN_RADIUS_FRACTION * R without a limit.  The search covers n_entry entry
    angles (plus the angle of the one-arc path onto the orbit and the leader's own polar
    angle) times a geometric spread of |r_A| of both signs plus boundary candidates
    (|r_A| = r_min, |r_B| = r_min, r_B = s R), then refines locally (finer phi and |r_A|)
    around the best few local minima over phi, keeping the shortest feasible candidate.
    Degenerate candidates (alpha == beta, r_A == p1, r_A + r_B == 0) are skipped.  If no
    candidate is feasible the grid is widened.  Raises ValueError only for bad inputs
    or when R < r_min (the orbit itself would exceed the turn-rate limit).
    """
    s = _check_inputs(v, radius, direction, max_turn_rate)
    x, y, heading = float(x), float(y), float(heading)
    r_min = _min_radius(v, radius, max_turn_rate)
    if radius < r_min * (1.0 - 1e-9):
        raise ValueError(f"orbit radius {radius} m is below the minimum turn radius {r_min} m")
    r_min = min(r_min, radius)

    r = math.hypot(x, y)
    theta = math.atan2(y, x)
    if (
        abs(r - radius) < _ON_ORBIT_TOL * max(1.0, radius)
        and abs(wrap(heading - theta - s * 0.5 * math.pi)) < _ON_ORBIT_TOL
    ):
        return _orbit_path(x, y, v, radius, s)

    alpha = wrap(heading)
    big = max(radius, r, r_min)
    r_cap = 1e3 * big
    extra = [theta]
    phi1 = _single_arc_phi(x, y, alpha, radius, s)
    if phi1 is not None:
        extra.append(phi1)

    coarse = None
    n_phi, n_mag, top = max(int(n_entry), 4), 24, 100.0
    for _ in range(4):  # widen until something is feasible
        phis = np.concatenate([np.arange(n_phi) * (TAU / n_phi), extra])
        mags = r_min * np.geomspace(1.0, max(2.0, top * big / r_min), n_mag)
        coarse = _best_cc(x, y, alpha, radius, s, r_min, r_cap, phis, mags, n_best=_N_STARTS, n_ring=n_phi)
        if coarse is not None:
            break
        n_phi, n_mag, top = 4 * n_phi, 2 * n_mag, 10.0 * top
    if coarse is None:  # pragma: no cover - not observed; keep the contract explicit
        raise RuntimeError("no feasible CC path found")

    # local refinement in (phi, |r_A|) around the best few entry angles (several basins:
    # the optimum often sits where |r_A| = |r_B| = r_min, between grid angles)
    ratio0 = (max(2.0, top * big / r_min)) ** (1.0 / (n_mag - 1))
    best = coarse[0]
    for start in coarse:
        cur, h, ratio = start, TAU / n_phi, ratio0
        for _ in range(3):
            _, ra_cur, _, phi_cur = cur
            phis = phi_cur + np.linspace(-h, h, 21)
            mags = np.abs(ra_cur) * np.geomspace(1.0 / ratio, ratio, 15)
            mags = mags[mags >= r_min]
            cand = _best_cc(x, y, alpha, radius, s, r_min, r_cap, phis, mags)
            if cand is not None and cand[0][0] < cur[0]:
                cur = cand[0]
            h, ratio = h / 10.0, math.sqrt(ratio)
        if cur[0] < best[0]:
            best = cur

    length, ra, rb, phi = best
    beta = phi + s * 0.5 * math.pi
    # recompute the arc angles in scalar form for the chosen candidate
    ax, ay = x - radius * math.cos(phi), y - radius * math.sin(phi)
    oax, oay = ax + ra * math.sin(alpha), ay - ra * math.cos(alpha)
    obx, oby = -rb * math.sin(beta), rb * math.cos(beta)
    ssum = ra + rb
    gt = math.atan2((oax - obx) / ssum, -(oay - oby) / ssum)
    d1 = math.fmod(-math.copysign(1.0, ra) * (gt - alpha), TAU) % TAU
    d2 = math.fmod(math.copysign(1.0, rb) * (beta - gt), TAU) % TAU
    scene = max(math.hypot(ax, ay), radius)
    d1 = 0.0 if _snap(d1, ra, scene) else d1
    d2 = 0.0 if _snap(d2, rb, scene) else d2
    t1, t2 = abs(ra) * d1 / v, abs(rb) * d2 / v
    entry = (radius * math.cos(phi), radius * math.sin(phi), wrap(beta))
    return CCPath(r_a=ra, r_b=rb, u1=-v / ra, u2=v / rb, t1=t1, t2=t2, entry=entry, length=abs(ra) * d1 + abs(rb) * d2)
