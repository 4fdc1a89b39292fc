"""Leader guidance: circle-circle (CC) path onto a circular orbit, then orbit hold.

The leader is a unicycle  x' = v cos g,  y' = v sin g,  g' = u  (speed v in m/s,
turn rate u in rad/s, heading g in rad, counter-clockwise positive).  It must reach
the circular orbit of radius R (m) around a target, flown in direction s = +1 (ccw)
or s = -1 (cw), along two tangent circular arcs (Lemma 1 of Rao 2024), and then hold
that orbit with :func:`on_orbit_command`.

Lemma 1, with the entry pose B(b, beta) translated to the origin (angles unchanged)
and the start pose A(a, alpha):

* centre of arc 1  o_A = (a_x + r_A sin alpha, a_y - r_A cos alpha),
* centre of arc 2  o_B = (-r_B sin beta, r_B cos beta),

with SIGNED radii in the paper's convention: r_A > 0 turns clockwise
(u1 = -v / r_A), r_B > 0 turns counter-clockwise (u2 = +v / r_B).  The arcs are
tangent, |o_A - o_B|^2 = (r_A + r_B)^2, which is the hyperbola

    r_B = p3 / (r_A - p1) + p2,            D = 1 - cos(alpha - beta),
    p1 = (a_x sin beta  - a_y cos beta ) / D,
    p2 = (a_x sin alpha - a_y cos alpha) / D,
    p3 = ((a_x sin m - a_y cos m) / D)^2,  m = (alpha + beta) / 2,

and p3 equals |a|^2 / (2 D) + p1 p2 (checked in tests/test_leader.py).  Equivalently,
without the 1/D blow-up near alpha == beta,

    r_B = (|a|^2 / 2 + r_A Pa) / (r_A D - Pb),  Pa = D p2,  Pb = D p1,

which is the form :func:`plan_cc` evaluates (candidate by candidate).

At the tangent point T, n = (o_A - o_B) / (r_A + r_B), T = o_A - r_A n and the heading
there is gT = atan2(n_x, -n_y).  Arc 1 turns from alpha to gT in the sense
sigma_A = -sign(r_A) through d1 = (sigma_A (gT - alpha)) mod 2 pi, arc 2 from gT to beta
in the sense sigma_B = sign(r_B) through d2 = (sigma_B (beta - gT)) mod 2 pi; the
durations are t1 = |r_A| d1 / v and t2 = |r_B| d2 / v.

Pure functions on plain floats, standard library only: no numpy, so that a leader
process is as light as a follower's; no I/O, no middleware.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarm.contracts.orbits import TAU, wrap


#: Without a turn-rate limit the smallest admissible arc radius is this fraction of R,
#: i.e. the planned turn rates stay below 10x the orbit's own turn rate v / R.
DEFAULT_MIN_RADIUS_FRACTION = 0.1

#: Orbit-hold gains (dimensionless): desired heading leans atan(K_RADIAL (r - R)/R)
#: towards the orbit; heading error feedback gain is K_HEADING * v / R (1/s).  The
#: linearised radial error obeys e'' + K_H w0 e' + w0^2 (1 + K_H K_R) e = 0 with
#: w0 = v / R, i.e. poles at -2 w0 and -3 w0 for (K_R, K_H) = (1, 5): overdamped.
K_RADIAL = 1.0
K_HEADING = 5.0

_D_EPS = 1e-12          # alpha == beta (D ~ 0): no CC path through the Lemma 1 hyperbola
_ON_ORBIT_TOL = 1e-9    # plan_cc: "already on the orbit" tolerance (relative radius / rad)
_HOLD_DEADBAND = 1e-12  # on_orbit_command: errors below this are rounding, not drift
_ANGLE_SNAP = 1e-10     # an arc angle within this of 2 pi is a rounding of 0 (rad) ...
_LENGTH_SNAP = 1e-10    # ... if the arc length dropped is below this times the scene size
_MIN_GAP = 1e-6         # |r_A + r_B| below this times max(|r_A|, |r_B|, |a|, R): near-coincident
_TANGENCY_TOL = 1e-9    # relative residual of |o_A - o_B| = |r_A + r_B| accepted
_BOUNDARY_NUDGE = 1e-9  # radii placed exactly on r_min are pushed out by this fraction
_N_STARTS = 4           # plan_cc refines around this many of the best coarse entry angles


@dataclass(frozen=True)
class CCPath:
    """A circle-circle path onto the orbit, in the paper's signed-radius convention.

    r_a:    signed radius of arc 1 (m); > 0 turns clockwise.
    r_b:    signed radius of arc 2 (m); > 0 turns counter-clockwise.
    u1:     turn rate on arc 1 (rad/s) = -v / r_a.
    u2:     turn rate on arc 2 (rad/s) = +v / r_b.
    t1:     duration of arc 1 (s).
    t2:     duration of arc 2 (s).
    entry:  (x (m), y (m), heading (rad)) of the entry pose B, TARGET-CENTRED coordinates,
            heading wrapped to (-pi, pi].  B is on the orbit, tangent in its direction.
    length: total path length (m) = v (t1 + t2).
    """

    r_a: float
    r_b: float
    u1: float
    u2: float
    t1: float
    t2: float
    entry: tuple[float, float, float]
    length: float

    @property
    def duration(self) -> float:
        """Total time on the path (s)."""
        return self.t1 + self.t2


def cc_coefficients(ax: float, ay: float, alpha: float, beta: float) -> tuple[float, float, float]:
    """Lemma 1 coefficients (p1, p2, p3) of r_B = p3 / (r_A - p1) + p2.

    ax, ay: start position (m) with the entry point B at the origin; alpha: start heading
    (rad); beta: entry heading (rad).  p1, p2 in m, p3 in m^2 (paper's form).
    Raises ValueError when D = 1 - cos(alpha - beta) ~ 0 (parallel headings).
    """
    d = 2.0 * math.sin(0.5 * (alpha - beta)) ** 2  # = 1 - cos(alpha - beta), no cancellation
    if d < _D_EPS:
        raise ValueError(f"degenerate CC geometry: alpha == beta (D = {d:.3g})")
    p1 = (ax * math.sin(beta) - ay * math.cos(beta)) / d
    p2 = (ax * math.sin(alpha) - ay * math.cos(alpha)) / d
    m = 0.5 * (alpha + beta)
    p3 = ((ax * math.sin(m) - ay * math.cos(m)) / d) ** 2
    return p1, p2, p3


def cc_radius_b(r_a: float, p1: float, p2: float, p3: float) -> float:
    """Signed radius r_B (m) of arc 2 for a signed radius r_a (m) of arc 1 (Lemma 1).

    Raises ValueError when r_a == p1 (r_B infinite: arc 2 would be a straight line).
    """
    if abs(r_a - p1) <= 1e-15 * max(1.0, abs(p1)):
        raise ValueError("r_a == p1: arc 2 degenerates to a straight line")
    return p3 / (r_a - p1) + p2


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


def _snap(d: float, r: float, scene: float) -> bool:
    """True when an arc angle d (rad) of radius r (m) just short of 2 pi is a rounded 0.

    Dropping the gap 2 pi - d moves the end point by about |r| (2 pi - d) (m) and turns
    the end heading by 2 pi - d (rad); both must be negligible for the scene size (m).
    (Inlined in :func:`_best_cc`'s candidate loop; keep the two in step.)
    """
    gap = TAU - d
    return gap < _ANGLE_SNAP and abs(r) * gap <= _LENGTH_SNAP * scene


def _linspace(start: float, stop: float, num: int) -> list[float]:
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


def _geomspace(start: float, stop: float, num: int) -> list[float]:
    """numpy.geomspace(start, stop, num) for 0 < start, stop and num >= 2.

    numpy takes 10 ** linspace(log10(start), log10(stop), num) and then sets both ends
    exactly to start and stop; so does this.  Inner values can differ from numpy's in the
    last bits where numpy uses its own SIMD log10 / power (AVX-512 builds): harmless, the
    grid only seeds the search.
    """
    out = [10.0 ** e for e in _linspace(math.log10(start), math.log10(stop), num)]
    out[0] = start
    out[-1] = stop
    return out


def _best_cc(px, py, alpha, radius, s, r_min, r_cap, phis, mags, n_best=1, n_ring=0):
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
    It is the numpy planner it replaced (tests/cc_reference.py) operation for operation:
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
        if not d > _D_EPS:  # alpha == beta: no candidate at this entry angle
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
            dx = ax + ra * sa + rb * sb          # o_A - o_B
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
            if eligible[i] and not (per_phi[i] <= per_phi[i - 1 if i else n_ring - 1]
                                    and per_phi[i] <= per_phi[(i + 1) % n_ring]):
                eligible[i] = False
    order = sorted((i for i, ok in enumerate(eligible) if ok), key=per_phi.__getitem__)[:n_best]
    if not order:
        return None
    return [(per_phi[i], best_ra[i], best_rb[i], phis[i]) for i in order]


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
    return CCPath(r_a=-s * radius, r_b=s * radius, u1=s * v / radius, u2=s * v / radius,
                  t1=0.0, t2=0.0, entry=entry, length=0.0)


def plan_cc(x: float, y: float, heading: float, v: float, radius: float, direction: int,
            max_turn_rate: float | None = None, *, n_entry: int = 72) -> CCPath:
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
    if (abs(r - radius) < _ON_ORBIT_TOL * max(1.0, radius)
            and abs(wrap(heading - theta - s * 0.5 * math.pi)) < _ON_ORBIT_TOL):
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
        step = TAU / n_phi
        phis = [i * step for i in range(n_phi)] + extra
        mags = [r_min * g for g in _geomspace(1.0, max(2.0, top * big / r_min), n_mag)]
        coarse = _best_cc(x, y, alpha, radius, s, r_min, r_cap, phis, mags,
                          n_best=_N_STARTS, n_ring=n_phi)
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
            phis = [phi_cur + e for e in _linspace(-h, h, 21)]
            mags = [m for m in (abs(ra_cur) * g for g in _geomspace(1.0 / ratio, ratio, 15))
                    if m >= r_min]
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
    return CCPath(r_a=ra, r_b=rb, u1=-v / ra, u2=v / rb, t1=t1, t2=t2, entry=entry,
                  length=abs(ra) * d1 + abs(rb) * d2)


def on_orbit_command(x: float, y: float, heading: float, v: float, radius: float, direction: int,
                     max_turn_rate: float | None = None) -> float:
    """Orbit-hold turn rate (rad/s) for a leader near its orbit.

    x, y: position relative to the target (m); heading (rad); v (m/s); radius R (m);
    direction +1 ccw / -1 cw; max_turn_rate (rad/s) or None.

    u = s v / R + K_HEADING (v / R) wrap(g_d - g),
    g_d = theta + s (pi / 2 + atan(K_RADIAL (r - R) / R)),

    so the correction is zero on the orbit with tangent heading (errors below 1e-12 are
    treated as rounding and give exactly s v / R) and pulls radial / heading errors back
    without overshoot.  Saturated at +-max_turn_rate when given.
    """
    s = _check_inputs(v, radius, direction, max_turn_rate)
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
