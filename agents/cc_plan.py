"""The circle-circle (CC) planner: a leader's path onto its circular orbit.

The leader is a unicycle  x' = v cos g,  y' = v sin g,  g' = u  (speed v in m/s,
turn rate u in rad/s, heading g in rad, counter-clockwise positive).  It must reach
the circular orbit of radius R (m) around a target, flown in direction s = +1 (ccw)
or s = -1 (cw), along two tangent circular arcs (Lemma 1 of Rao 2024), and then hold
that orbit (agents/leader.py).

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

and p3 equals |a|^2 / (2 D) + p1 p2 (checked in tests/process/test_leader.py).  Equivalently,
without the 1/D blow-up near alpha == beta,

    r_B = (|a|^2 / 2 + r_A Pa) / (r_A D - Pb),  Pa = D p2,  Pb = D p1,

which is the form :func:`plan_cc` evaluates (candidate by candidate).

At the tangent point T, n = (o_A - o_B) / (r_A + r_B), T = o_A - r_A n and the heading
there is gT = atan2(n_x, -n_y).  Arc 1 turns from alpha to gT in the sense
sigma_A = -sign(r_A) through d1 = (sigma_A (gT - alpha)) mod 2 pi, arc 2 from gT to beta
in the sense sigma_B = sign(r_B) through d2 = (sigma_B (beta - gT)) mod 2 pi; the
durations are t1 = |r_A| d1 / v and t2 = |r_B| d2 / v.

:func:`plan_cc` searches a grid of entry angles and radii (its candidate loop, with the
numerical guards, is agents/cc_grid.py) and refines around the best.  Pure functions on
plain floats, standard library only: no numpy, so that a leader process is as light as a
follower's; no I/O, no middleware.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from swarm.agents.cc_grid import D_EPS, best_cc, geomspace, linspace, snap
from swarm.contracts.orbits import TAU, wrap

#: Without a turn-rate limit the smallest admissible arc radius is this fraction of R,
#: i.e. the planned turn rates stay below 10x the orbit's own turn rate v / R.
DEFAULT_MIN_RADIUS_FRACTION = 0.1

_ON_ORBIT_TOL = 1e-9  # plan_cc: "already on the orbit" tolerance (relative radius / rad)
_N_STARTS = 4  # plan_cc refines around this many of the best coarse entry angles


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
    if d < D_EPS:
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


def check_inputs(v: float, radius: float, direction: int, max_turn_rate: float | None) -> int:
    """The direction (+1 / -1) of valid inputs, shared with the orbit hold; else ValueError."""
    if not (v > 0.0 and math.isfinite(v)):
        raise ValueError(f"speed must be > 0, got {v!r}")
    if not (radius > 0.0 and math.isfinite(radius)):
        raise ValueError(f"orbit radius must be > 0, got {radius!r}")
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 (ccw) or -1 (cw), got {direction!r}")
    if max_turn_rate is not None and not max_turn_rate > 0.0:
        raise ValueError(f"max_turn_rate must be > 0 or None, got {max_turn_rate!r}")
    return int(direction)


def _single_arc_phi(px: Any, py: Any, alpha: Any, radius: Any, s: Any) -> Any:
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


def _orbit_path(x: Any, y: Any, v: Any, radius: Any, s: Any) -> CCPath:
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
    s = check_inputs(v, radius, direction, max_turn_rate)
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
        step = TAU / n_phi
        phis = [i * step for i in range(n_phi)] + extra
        mags = [r_min * g for g in geomspace(1.0, max(2.0, top * big / r_min), n_mag)]
        coarse = best_cc(x, y, alpha, radius, s, r_min, r_cap, phis, mags, n_best=_N_STARTS, n_ring=n_phi)
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
            phis = [phi_cur + e for e in linspace(-h, h, 21)]
            mags = [m for m in (abs(ra_cur) * g for g in geomspace(1.0 / ratio, ratio, 15)) if m >= r_min]
            cand = best_cc(x, y, alpha, radius, s, r_min, r_cap, phis, mags)
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
    d1 = 0.0 if snap(d1, ra, scene) else d1
    d2 = 0.0 if snap(d2, rb, scene) else d2
    t1, t2 = abs(ra) * d1 / v, abs(rb) * d2 / v
    entry = (radius * math.cos(phi), radius * math.sin(phi), wrap(beta))
    return CCPath(r_a=ra, r_b=rb, u1=-v / ra, u2=v / rb, t1=t1, t2=t2, entry=entry, length=abs(ra) * d1 + abs(rb) * d2)
