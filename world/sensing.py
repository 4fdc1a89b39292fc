"""Simulated sensors: who senses whom, and each agent's own sensor frame.

A frame holds only what the agent's sensors give it (paper, section "Main Results"):
for every agent it can sense, the line-of-sight angle lambda_ij, that agent's heading
and a range (used only to rank candidates), plus its own heading; leaders also get
the target's position relative to themselves. Pure numpy, no I/O.
"""

from __future__ import annotations

import numpy as np

from swarm.contracts.frames import Contact, SensorFrame
from world.kinematics import wrap

__all__ = ["Contact", "SensorFrame", "sensing_matrix", "build_frames"]


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


def build_frames(tick, time, ids, x, y, heading, present, receivers, is_leader, target,
                 sense_range=None, fov=None, hops=None, matrices=None) -> dict[int, SensorFrame]:
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
