"""Simulated sensors: who senses whom, and each agent's own sensor frame.

A frame holds only what the agent's sensors give it (paper, section "Main Results"):
for every agent it can sense, the line-of-sight angle lambda_ij, that agent's heading
and a range (used only to rank candidates), plus its own heading; leaders also get
the target's position relative to themselves. Pure numpy, no I/O.
"""

from __future__ import annotations

import numpy as np

from swarm.contracts import wire
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.orbits import wrap as wrap_one
from swarm.world.kinematics import wrap

__all__ = ["Contact", "SensorFrame", "sensing_matrix", "build_frames", "encode_frames_pairwise"]


def sensing_matrix(x, y, heading, present, sense_range: float | None, fov: float | None):
    """Boolean (N, N) matrix S with S[i, j] true when agent i senses agent j.

    present: (N,) bool, agents that are in the world. sense_range (m) or None for
    unlimited; fov: full field of view (rad) centred on the heading, or None.
    Also returns the bearing (N, N) and range (N, N) matrices. Bearings are computed only
    for the pairs within range (NaN elsewhere): with a sensing range the arctangents, the
    costliest part, grow with the pairs sensed rather than with N^2.
    """
    dx = x[None, :] - x[:, None]
    dy = y[None, :] - y[:, None]
    rng = np.hypot(dx, dy)
    s = present[:, None] & present[None, :]
    np.fill_diagonal(s, False)
    if sense_range is None:
        bearing = np.arctan2(dy, dx)
    else:
        s &= rng <= sense_range
        bearing = np.full(rng.shape, np.nan)
        bearing[s] = np.arctan2(dy[s], dx[s])
    if fov is not None and fov < 2 * np.pi:
        i, j = np.nonzero(s)
        s[i, j] = np.abs(wrap(bearing[i, j] - heading[i])) <= 0.5 * fov
    return s, bearing, rng


def build_frames(
    tick,
    time,
    ids,
    x,
    y,
    heading,
    present,
    receivers,
    is_leader,
    target,
    sense_range=None,
    fov=None,
    hops=None,
    matrices=None,
) -> dict[int, SensorFrame]:
    """One SensorFrame per receiver index (agents that need a frame this tick).

    hops: (N,) hop counts the agents last advertised (-1 none); the world relays them
    like a local broadcast that reaches exactly the agents that sense the sender.
    matrices: this tick's sensing_matrix result if already computed.
    """
    s, bearing, rng = matrices or sensing_matrix(x, y, heading, present, sense_range, fov)
    if hops is None:
        hops = np.full(len(ids), -1)
    frames: dict[int, SensorFrame] = {}
    for i in receivers:
        contacts = tuple(
            Contact(int(ids[j]), float(bearing[i, j]), float(heading[j]), float(rng[i, j]), int(hops[j]))
            for j in np.flatnonzero(s[i])
        )
        tgt = (float(target[0] - x[i]), float(target[1] - y[i])) if is_leader[i] else None
        frames[int(ids[i])] = SensorFrame(int(tick), float(time), int(ids[i]), float(heading[i]), contacts, tgt)
    return frames


def encode_frames_pairwise(
    tick: int,
    time: float,
    receivers,
    ids,
    x,
    y,
    heading,
    present,
    is_leader,
    target,
    sense_range: float | None,
    fov: float | None,
    hops,
) -> list[bytes]:
    """The encoded frames of the receivers (indices), the bytes of
    wire.encode_sense_rows(..., *sensing_matrix(...)), computed pair by pair on Python
    floats: a small swarm's frames cost fewer numpy calls this way (two: every range, then
    the bearings sensed, with numpy's own hypot and arctan2, so the bits are the matrix's)."""
    xs, ys, gs = x.tolist(), y.tolist(), heading.tolist()
    idl, hl, lead, pres = ids.tolist(), hops.tolist(), is_leader.tolist(), present.tolist()
    n = len(xs)
    pairs, dxs, dys = [], [], []
    for i in receivers:
        if pres[i]:
            xi, yi = xs[i], ys[i]
            for j in range(n):
                if j != i and pres[j]:
                    pairs.append((i, j))
                    dxs.append(xs[j] - xi)
                    dys.append(ys[j] - yi)
    rng = np.hypot(dxs, dys).tolist()
    seen = [k for k, r in enumerate(rng) if sense_range is None or r <= sense_range]
    bearing = np.arctan2([dys[k] for k in seen], [dxs[k] for k in seen]).tolist()
    contacts: dict[int, list] = {i: [] for i in receivers}
    cone = None if fov is None or fov >= 2 * np.pi else 0.5 * fov
    for k, b in zip(seen, bearing):
        i, j = pairs[k]
        if cone is None or abs(wrap_one(b - gs[i])) <= cone:
            contacts[i].append((idl[j], b, gs[j], rng[k], hl[j]))
    tx, ty = target
    return [
        wire.encode_sense_tuples(tick, time, idl[i], gs[i], (tx - xs[i], ty - ys[i]) if lead[i] else None, contacts[i])
        for i in receivers
    ]
