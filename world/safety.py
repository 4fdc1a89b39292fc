"""The safety filter: control barrier functions on the unicycle, one small QP per tick.

Pure maths, no I/O: given every agent's pose, speed, the turn rate its law asked for and
its limit, `safe_commands` returns the commands closest to the law's that keep every
barrier's condition, and which barriers were active. The world applies it between the
commands it latched and the integration (or the robots): world/safety_watch.py.
docs/design/safety.md says what it promises and what not.

The model. Agent i is a unicycle at position p_i, heading g_i, speed v_i, turn rate u_i.
Its position's velocity v_i (cos g_i, sin g_i) does not depend on u_i, so a barrier on the
position has relative degree 2 in u. The standard way round (Robotarium's
`create_unicycle_barrier_certificate`) is a point `lookahead` l ahead of the agent,

    q_i = p_i + l e_i,   dq_i/dt = v_i e_i + l u_i n_i,   e_i = (cos g_i, sin g_i), n_i = (-sin g_i, cos g_i),

whose velocity is linear in (u_i, v_i). The barriers are distances of those points:

- a pair:  h_ij = |q_i - q_j| - (radius + 2 l)   (>= 0 keeps |p_i - p_j| >= radius);
- a wall:  h_ik = a_k . q_i - c_k - (radius / 2 + l), the arena being the convex polygon
  a_k . p >= c_k (unit inward normals a_k): >= 0 keeps p_i radius / 2 inside every wall;

and the condition on each is dh/dt >= -gamma h (gamma in 1/s: a barrier may shrink at most
at the rate gamma times what is left of it, so it is approached, never crossed, in
continuous time). Each condition is one linear inequality in the commands:

    pair:  l (d . n_i) u_i - l (d . n_j) u_j + (d . e_i) v_i - (d . e_j) v_j >= -gamma h_ij
           (d = (q_i - q_j) / |q_i - q_j|)
    wall:  l (a_k . n_i) u_i + (a_k . e_i) v_i >= -gamma h_ik

The QP: minimise sum (u_i - u_law_i)^2 (+ sum ((v_i - v_i0) / l)^2 when speed may change:
both terms are then the change of the lookahead point's velocity, in (m/s)^2 / l^2) subject
to those inequalities, |u_i| <= max_turn_rate_i and, when speed may change, 0 <= v_i <= v_i0.
Agents that are not controlled (coasting: u = 0) are obstacles with known velocities.

What is solved, and how:

- the law's command is checked first (with numpy, exactly): when it keeps every condition
  it is returned unchanged, bit for bit, and no QP is solved;
- a condition that no command within the limits can break is left out (exact: it cannot
  bind), and the agents are split into groups joined by the conditions left; only the
  groups with a broken condition are solved, the others keep their law's commands;
- each group's QP is solved by DAQP (a dual active-set method for small dense QPs:
  MIT-licensed, exact active set, deterministic, simple bounds native; pyproject.toml says
  why it and not another) and its answer checked again with numpy;
- no command within the limits keeps every condition (an "infeasible" group, e.g. two
  constant-speed agents head on): when speed may change, the group stops (v = 0, u = 0:
  nothing of it moves closer); when it may not (the paper's agents only turn), the least
  violating command is applied, from the same QP with a slack per condition weighted
  SLACK_WEIGHT. Either way the agents are marked infeasible, for the record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import daqp
import numpy as np

from swarm.contracts.scenario_tables import SafetySpec, is_convex_polygon, polygon_turns

INF = 1e30  # DAQP's infinity (a bound at or beyond it is no bound)
SLACK_WEIGHT = 1e6  # infeasible groups: cost of a unit of broken condition, per unit (rad/s)^2 of turn rate
CHECK_TOL = 1e-9  # m/s: a solved command breaking a condition by more is refused (the solver is checked too)
CHANGED_TOL = 1e-12  # rad/s and m/s: a solved command this close to the law's counts as unchanged


@dataclass(frozen=True)
class Arena:
    """A convex polygon as half-planes: p is inside iff normals @ p >= offsets (each row
    a unit inward normal); wall k runs from vertices[k] to vertices[k + 1], the corners in
    the order given (a "safety" event's "wall k" is the one from corner k to k + 1)."""

    vertices: tuple[tuple[float, float], ...]
    normals: np.ndarray = field(repr=False, compare=False)
    offsets: np.ndarray = field(repr=False, compare=False)

    @classmethod
    def polygon(cls, points: Any) -> Arena:
        """A convex polygon from its corners in either order (ValueError otherwise)."""
        pts = [(float(x), float(y)) for x, y in points]
        if len(pts) < 3:
            raise ValueError(f"a polygon needs 3 corners or more, got {len(pts)}")
        if not is_convex_polygon(pts):
            raise ValueError("the polygon is not convex (or has repeated or collinear corners, or crosses itself)")
        turns = polygon_turns(pts)
        p = np.array(pts)
        nxt = np.roll(p, -1, axis=0)
        edge = nxt - p
        left = np.stack([-edge[:, 1], edge[:, 0]], axis=1) / np.hypot(edge[:, 0], edge[:, 1])[:, None]
        ccw = turns[0] > 0  # the inside is left of each wall walked counter-clockwise, right of it clockwise
        normals = left if ccw else -left
        # a wall's offset from its corner where a counter-clockwise walk starts it (either is exact)
        offsets = np.einsum("ij,ij->i", normals, p if ccw else nxt)
        return cls(tuple(pts), normals, offsets)

    @classmethod
    def rectangle(cls, xmin: float, ymin: float, xmax: float, ymax: float) -> Arena:
        return cls.polygon([(xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax)])

    def depth(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(..., K) signed distance of each point inside each wall (negative: outside it)."""
        return (
            np.asarray(x)[..., None] * self.normals[:, 0] + np.asarray(y)[..., None] * self.normals[:, 1] - self.offsets
        )

    def inside(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.asarray((self.depth(x, y) >= 0.0).all(axis=-1))


@dataclass(frozen=True)
class Barriers:
    """The filter's parameters (a scenario's [safety] table, swarm/contracts/scenario_tables.py)."""

    radius: float  # m: the least distance between two agents' positions
    lookahead: float  # m: l, the point ahead of each agent the barriers are on
    gamma: float  # 1/s: dh/dt >= -gamma h
    arena: Arena | None = None
    speed: bool = False  # may the filter change speeds (slow down, stop): robots that allow it

    def __post_init__(self) -> None:
        # a scenario's [safety] table is checked where it is read; these are for the Python API
        for name in ("radius", "lookahead", "gamma"):
            value = getattr(self, name)
            try:
                ok = math.isfinite(value) and value > 0
            except TypeError:
                ok = False
            if not ok:
                raise ValueError(f"Barriers.{name} must be a finite number > 0, got {value!r}")

    @property
    def pair_distance(self) -> float:
        """m: the least distance between two lookahead points."""
        return self.radius + 2.0 * self.lookahead

    @property
    def wall_margin(self) -> float:
        """m: the least distance of a lookahead point inside a wall."""
        return 0.5 * self.radius + self.lookahead


def barriers_of(spec: SafetySpec) -> Barriers:
    """A scenario's [safety] table as the filter's parameters."""
    corners = spec.corners
    return Barriers(
        radius=spec.radius,
        lookahead=spec.lookahead_m,
        gamma=spec.gamma,
        arena=None if corners is None else Arena.polygon(corners),
        speed=spec.speed,
    )


@dataclass
class Conditions:
    """The barrier conditions of one state, one row each, each on at most two agents:

        ua u[a] + va v[a] + ub u[b] + vb v[b] >= rhs     (a pair: agents a < b)
        ua u[a] + va v[a] >= rhs                         (a wall: agent a, wall b; ub = vb = 0)

    h[r] is the barrier's value (m). Kept per row, not as (rows x agents) matrices: with N
    agents there are N (N - 1) / 2 pairs."""

    wall: np.ndarray  # (R,) bool
    a: np.ndarray  # (R,) int: an agent's column
    b: np.ndarray  # (R,) int: the other agent's column (a pair), the wall's index (a wall)
    h: np.ndarray
    ua: np.ndarray
    va: np.ndarray
    ub: np.ndarray
    vb: np.ndarray
    rhs: np.ndarray
    other: np.ndarray = field(init=False)  # (R,) the second agent's column (a wall's: its own, ub = vb = 0)

    def __post_init__(self) -> None:
        self.other = np.where(self.wall, self.a, self.b)

    def slack(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(R,) how far each condition holds with commands (u, v) (negative: broken)."""
        o = self.other
        return self.ua * u[self.a] + self.va * v[self.a] + self.ub * u[o] + self.vb * v[o] - self.rhs

    def on(self, rows: np.ndarray, members: np.ndarray, n: int, u: np.ndarray, v: np.ndarray) -> Any:
        """The rows as matrices on the commands of `members` (of n agents): (cu, cv), each
        (len(rows), len(members)), and the rows' right sides less the terms of the agents
        that are not members, whose commands are (u, v)."""
        col = np.full(n, -1)
        col[members] = np.arange(len(members))
        a, o = self.a[rows], self.other[rows]
        ca, co = col[a], col[o]
        ua, va, ub, vb = self.ua[rows], self.va[rows], self.ub[rows], self.vb[rows]
        fixed = np.where(ca < 0, ua * u[a] + va * v[a], 0.0) + np.where(co < 0, ub * u[o] + vb * v[o], 0.0)
        cu, cv = np.zeros((len(rows), len(members))), np.zeros((len(rows), len(members)))
        ra, ro = np.flatnonzero(ca >= 0), np.flatnonzero(co >= 0)
        cu[ra, ca[ra]] += ua[ra]
        cv[ra, ca[ra]] += va[ra]
        cu[ro, co[ro]] += ub[ro]
        cv[ro, co[ro]] += vb[ro]
        return cu, cv, self.rhs[rows] - fixed


def conditions(bar: Barriers, x: np.ndarray, y: np.ndarray, g: Any, present: np.ndarray) -> Conditions:
    """Every barrier condition between present agents (pairs i < j) and of each present
    agent with each wall. x, y, g: (N,) poses (m, m, rad)."""
    x, y, g = (np.asarray(a, dtype=float) for a in (x, y, g))
    la = bar.lookahead
    c, s = np.cos(g), np.sin(g)
    qx, qy = x + la * c, y + la * s
    i, j = pairs(present)
    dx, dy = qx[i] - qx[j], qy[i] - qy[j]
    dist = np.hypot(dx, dy)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux, uy = np.where(dist > 0, dx / dist, 1.0), np.where(dist > 0, dy / dist, 0.0)
    parts = [
        (
            np.zeros(len(i), dtype=bool),
            i,
            j,
            dist - bar.pair_distance,
            la * (-ux * s[i] + uy * c[i]),
            ux * c[i] + uy * s[i],
            -la * (-ux * s[j] + uy * c[j]),
            -(ux * c[j] + uy * s[j]),
        )
    ]
    if bar.arena is not None:
        idx = np.flatnonzero(present)
        K = len(bar.arena.offsets)
        k = np.repeat(idx, K)
        w = np.tile(np.arange(K), len(idx))
        ax, ay = bar.arena.normals[w, 0], bar.arena.normals[w, 1]
        depth = bar.arena.depth(qx[idx], qy[idx]).reshape(-1)
        zero = np.zeros(len(k))
        parts.append(
            (
                np.ones(len(k), dtype=bool),
                k,
                w,
                depth - bar.wall_margin,
                la * (-ax * s[k] + ay * c[k]),
                ax * c[k] + ay * s[k],
                zero,
                zero,
            )
        )
    wall, a, b, h, ua, va, ub, vb = (np.concatenate(col) for col in zip(*parts))
    return Conditions(wall, a, b, h, ua, va, ub, vb, -bar.gamma * h)


@dataclass
class Filtered:
    """What the filter did this tick: the commands to apply, per agent whether they differ
    from the law's (`changed`) and whether no safe command existed (`infeasible`), and the
    conditions that bound the answer (`active`: rows of `cond`)."""

    u: np.ndarray
    v: np.ndarray
    changed: np.ndarray
    infeasible: np.ndarray
    cond: Conditions | None = None
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    solves: int = 0  # QPs solved (0: the law's commands were safe)

    def reasons(self, k: int) -> list[tuple[str, int]]:
        """What bound agent k's command: ("agent", its column) / ("wall", its index) per active condition."""
        if self.cond is None:
            return []
        c = self.cond
        out = []
        for r in self.active.tolist():
            if not c.wall[r] and k in (c.a[r], c.b[r]):
                out.append(("agent", int(c.b[r] if c.a[r] == k else c.a[r])))
            elif c.wall[r] and c.a[r] == k:
                out.append(("wall", int(c.b[r])))
        return out


def safe_commands(
    bar: Barriers,
    x: Any,
    y: Any,
    g: Any,
    v0: Any,
    u_law: Any,
    u_max: Any,
    present: np.ndarray,
    controlled: np.ndarray | None = None,
) -> Filtered:
    """The commands closest to the law's that keep every barrier's condition.

    x, y, g, v0, u_law, u_max: (N,) poses, speeds (m/s), the law's turn rates (rad/s;
    within their limits) and the limits (rad/s; inf: none). present: (N,) agents in the
    world (the others are ignored); controlled: (N,) those whose commands may change (the
    others, e.g. coasting, keep theirs and are obstacles; default: every present one).
    Agents not present keep their (u_law, v0), and so does an agent whose pose, speed or
    command is not finite: it is ignored as one not present (nothing is known of where it
    goes; its NaN in a condition would leave that condition unchecked and its group's QP
    unsolvable, the filter off for every agent joined to it)."""
    u_law = np.asarray(u_law, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    x, y, g = (np.asarray(a, dtype=float) for a in (x, y, g))
    n = len(u_law)
    finite = np.isfinite(x) & np.isfinite(y) & np.isfinite(g) & np.isfinite(v0) & np.isfinite(u_law)
    present = np.asarray(present, dtype=bool) & finite
    ctl = present.copy() if controlled is None else np.asarray(controlled, dtype=bool) & present
    u, v = u_law.copy(), v0.copy()
    none = np.zeros(n, dtype=bool)
    if present.sum() == 0:
        return Filtered(u, v, none, none.copy())
    cond = conditions(bar, x, y, g, present)
    # u_law of an agent not present may be NaN: it has no condition, so it counts as zero
    u_in, v_in = np.where(present, u_law, 0.0), np.where(present, v0, 0.0)
    slack = cond.slack(u_in, v_in)
    broken = slack < 0.0
    if not broken.any():
        return Filtered(u, v, none, none.copy(), cond)
    u_max = np.asarray(u_max, dtype=float)
    # drop conditions that no command within the limits can break: their least left side
    # over the box of commands still meets the right side
    umax_c = np.where(ctl, u_max, 0.0)
    o = cond.other

    def least(cu: Any, cv: Any, col: Any) -> Any:
        """The least of cu u[col] + cv v[col] over the box (fixed commands: their value)."""
        with np.errstate(invalid="ignore"):  # 0 x inf, in the branch not taken
            lu = np.where(ctl[col], np.where(cu != 0.0, -np.abs(cu) * umax_c[col], 0.0), cu * u_in[col])
        lv = cv * v_in[col]
        return lu + (np.where(ctl[col], np.minimum(0.0, lv), lv) if bar.speed else lv)

    with np.errstate(invalid="ignore"):
        may_bind = ~(least(cond.ua, cond.va, cond.a) + least(cond.ub, cond.vb, o) >= cond.rhs)
    rows = np.flatnonzero(may_bind | broken)
    groups = _groups(cond, rows, ctl, n)
    changed, infeasible = none.copy(), none.copy()
    active: list[int] = []
    solves = 0
    for members, grows in groups:
        if not broken[grows].any():
            continue
        solves += 1
        gu, gv, ok, act = _solve(bar, cond, grows, members, u_in, v_in, umax_c)
        if not ok:
            infeasible[members] = True
        u[members], v[members] = gu, gv
        active.extend(act)
    with np.errstate(invalid="ignore"):  # inf - inf of an agent left out (not finite): not changed
        changed = ctl & ((np.abs(u - u_law) > CHANGED_TOL) | (np.abs(v - v0) > CHANGED_TOL) | infeasible)
    return Filtered(u, v, changed, infeasible, cond, np.array(sorted(active), dtype=np.int64), solves)


def _groups(cond: Conditions, rows: np.ndarray, ctl: np.ndarray, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The controlled agents joined by the conditions `rows` (union-find), each group with
    its conditions: [(agent columns, condition rows)]."""
    parent = list(range(n))

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    ctl_l = ctl.tolist()
    for r in rows.tolist():
        a = int(cond.a[r])
        if not cond.wall[r]:
            b = int(cond.b[r])
            if ctl_l[a] and ctl_l[b]:
                ra, rb = find(a), find(b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    by_root: dict[int, list[int]] = {}
    for r in rows.tolist():
        a = int(cond.a[r])
        k = a if ctl_l[a] else (int(cond.b[r]) if not cond.wall[r] and ctl_l[int(cond.b[r])] else -1)
        if k >= 0:  # a condition on no controlled agent cannot be helped: left to the record
            by_root.setdefault(find(k), []).append(r)
    out = []
    for root in sorted(by_root):
        members = np.array(sorted({k for k in range(n) if ctl_l[k] and find(k) == root}), dtype=np.int64)
        out.append((members, np.array(by_root[root], dtype=np.int64)))
    return out


def _solve(bar: Barriers, cond: Conditions, rows: Any, members: Any, u_in: Any, v_in: Any, umax_c: Any) -> Any:
    """One group's QP: (u, v) of its members, whether they keep every condition, and the
    active rows. Falls back to the stop (speed may change) or the least violating command."""
    m = len(members)
    A_u, A_v, rhs = cond.on(rows, members, len(u_in), u_in, v_in)
    ud, vd, um = u_in[members], v_in[members], umax_c[members]
    l2 = bar.lookahead**2
    if bar.speed:
        A = np.hstack([A_u, A_v])
        H = np.diag(np.concatenate([np.full(m, 2.0), np.full(m, 2.0 / l2)]))
        z0 = np.concatenate([ud, vd])
        lo = np.concatenate([-um, np.zeros(m)])
        hi = np.concatenate([um, vd])
        b = rhs
    else:
        A = A_u
        H = 2.0 * np.eye(m)
        z0 = ud
        lo, hi = -um, um
        b = rhs - A_v @ vd
    lo, hi = np.maximum(lo, -INF), np.minimum(hi, INF)
    z, flag = _qp(H, z0, A, b, lo, hi)
    nz = len(z0)
    if flag == 1 and np.all(A @ z - b >= -CHECK_TOL) and np.all(z >= lo - CHECK_TOL) and np.all(z <= hi + CHECK_TOL):
        z = np.clip(z, lo, hi)
        act = rows[np.abs(A @ z - b) <= 1e-6 * (1.0 + np.abs(b))]
        return z[:m], (z[m:] if bar.speed else vd.copy()), True, act.tolist()
    if bar.speed:  # no safe command: stop (nothing of the group moves closer)
        return np.zeros(m), np.zeros(m), False, rows.tolist()
    # the least violating turn rates: a slack per condition, dearly paid
    R = len(b)
    H2 = np.zeros((nz + R, nz + R))
    H2[:nz, :nz] = H
    H2[nz:, nz:] = 2.0 * SLACK_WEIGHT * np.eye(R)
    A2 = np.hstack([A, np.eye(R)])
    z2, flag2 = _qp(
        H2,
        np.concatenate([z0, np.zeros(R)]),
        A2,
        b,
        np.concatenate([lo, np.full(R, -INF)]),
        np.concatenate([hi, np.full(R, INF)]),
    )
    gu = np.clip(z2[:m], -um, um) if flag2 == 1 else np.clip(ud, -um, um)
    return gu, vd.copy(), False, rows.tolist()


def _qp(H: Any, z0: Any, A: Any, b: Any, lo: Any, hi: Any) -> tuple[np.ndarray, int]:
    """min 1/2 z'Hz - (H z0)'z s.t. A z >= b, lo <= z <= hi, by DAQP: (z, exit flag; 1 = optimal)."""
    nz = len(z0)
    bupper = np.concatenate([hi, np.full(len(b), INF)])
    blower = np.concatenate([lo, b])
    sense = np.zeros(nz + len(b), dtype=np.int32)
    try:
        z, _, flag, _ = daqp.solve(
            np.ascontiguousarray(H, dtype=float),
            np.ascontiguousarray(-(H @ z0), dtype=float),
            np.ascontiguousarray(A, dtype=float),
            np.ascontiguousarray(bupper, dtype=float),
            np.ascontiguousarray(blower, dtype=float),
            sense,
            primal_tol=1e-12,
        )
    except Exception:  # a solver that fails is a solver that found nothing
        return np.asarray(z0, dtype=float).copy(), -99
    z = np.asarray(z, dtype=float)
    if z.shape != (nz,) or not np.all(np.isfinite(z)):
        return np.asarray(z0, dtype=float).copy(), -99
    return z, int(flag)


def distances(x: np.ndarray, y: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Distances (m) between the agents of columns i and j (`pairs`)."""
    return np.hypot(np.asarray(x)[i] - np.asarray(x)[j], np.asarray(y)[i] - np.asarray(y)[j])


def pairs(present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The columns (i, j), i < j, of every pair of present agents."""
    idx = np.flatnonzero(present)
    ii, jj = _triu(len(idx))
    return idx[ii], idx[jj]


@lru_cache(maxsize=64)
def _triu(n: int) -> tuple[np.ndarray, np.ndarray]:
    """np.triu_indices(n, 1), made once per n (it costs tens of microseconds)."""
    ii, jj = np.triu_indices(n, 1)
    ii.flags.writeable = jj.flags.writeable = False
    return ii, jj


__all__ = [
    "Arena",
    "Barriers",
    "Conditions",
    "Filtered",
    "barriers_of",
    "conditions",
    "distances",
    "pairs",
    "safe_commands",
]
