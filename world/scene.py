"""What Foxglove draws and plots of a run, built from one tick's arrays, and the channels it is
logged on (`SceneChannels`): world/stream.py logs it to the recording (and so, with --foxglove,
to the world's live view, world/live_view.py); `swarm watch --foxglove` (swarm/live/foxglove.py)
builds the same from the ground truth an observer of a live run receives.

- `/swarm/scene`  foxglove.SceneUpdate: agents as arrows (leaders red, followers blue),
  out-neighbour edges as lines, the target as a sphere, each expected orbit as a circle
  (R_i = v_i * R_L / v_L of the leader at the end of the agent's path, grey dashed-less loop);
- `/swarm/trails` foxglove.SceneUpdate: each agent's path over the last TRAIL_SECONDS,
  one line strip per agent (less often than the scene: it is the bulk of the bytes);
- `/swarm/agents` JSON `{"tick", "time", "agents": [{"id", "role", "alive", "x", "y",
  "heading", "u", "out", "root", "expected_radius", "radial_error", "follow"}]}`: per-agent
  numbers to plot, e.g. `/swarm/agents.agents[:]{id==3}.radial_error` (`follow`: the follow
  state, keep / hold / coast / ...; `swarm watch --foxglove` takes it from the agents' statuses);
- `/swarm/events` JSON, one message per event; `/swarm/run` JSON, what the run is.

Only called at scene ticks (at most SCENE_RATE per simulated second), so a run pays for
none of it on the other ticks. Log times are simulated time in nanoseconds.
"""

from __future__ import annotations

import json
import math
from collections import deque
from typing import Any

import numpy as np

from swarm.contracts.orbits import expected_radius, roots
from swarm.contracts.scenario_tables import AgentSpec
from swarm.contracts.wire import FOLLOW_STATES

TRAIL_SECONDS = 30.0  # simulated s of path each trail shows
TRAIL_RATE = 2.0  # trail points per simulated second
TRAIL_EVERY = 5  # a trails message every this many scene updates
ORBIT_POINTS = 72
SCENE_RATE = 10.0  # scene updates per simulated second, at most


def log_time(t: float) -> int:
    """A log time: simulated time `t` (s) in nanoseconds."""
    return max(0, int(round(t * 1e9)))


class SceneBuilder:
    """Keeps what the scene needs beyond one tick (roles, speeds, orbits, trails). `agents`:
    what it needs of each agent, `.id`, `.role`, `.speed` and `.orbit_radius` (a scenario's
    AgentSpec has them)."""

    def __init__(self, target: tuple[float, float], agents: Any, scene_rate: float) -> None:
        self.target = (float(target[0]), float(target[1]))
        self.agents = list(agents)
        self.spec = {a.id: a for a in self.agents}
        self.leaders = {a.id for a in self.agents if a.role == "leader"}  # ids of the leader role
        self.trail_every = max(1, int(round(scene_rate / TRAIL_RATE)))
        self.trail_len = int(TRAIL_SECONDS * TRAIL_RATE)
        self.trails: dict[int, deque] = {}
        self.updates = 0
        self.radii: tuple = ()
        self.circles: list = []

    def add_agent(self, spec: AgentSpec) -> None:
        self.agents.append(spec)
        self.spec[spec.id] = spec
        if spec.role == "leader":
            self.leaders.add(spec.id)

    # -- per-agent numbers ------------------------------------------------------------------
    def numbers(
        self,
        tick: int,
        t: Any,
        ids: Any,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        follow: Any = None,
    ) -> dict:
        """follow: the agents' follow state codes (wire.FOLLOW_STATES), each agent's `follow`
        by name; None: no `follow` (an observer that does not know them)."""
        spec = self.spec
        leaders = {int(i) for k, i in enumerate(ids) if alive[k] and int(i) in self.leaders}
        outs = {int(i): (int(out[k]) if out[k] >= 0 else None) for k, i in enumerate(ids)}
        tx, ty = self.target
        rooted = roots(outs, leaders)
        rows = []
        for k, i in enumerate(ids):
            i = int(i)
            a = spec[i]
            root = rooted[i] if alive[k] else None
            R: float | None = None
            err: float | None = None
            if root is not None:
                L = spec[root]
                R = expected_radius(a.speed, L.speed, L.orbit_radius)
                err = abs(math.hypot(float(x[k]) - tx, float(y[k]) - ty) - R)
            uk = float(u[k])
            rows.append(
                {
                    "id": i,
                    "role": a.role,
                    "alive": bool(alive[k]),
                    "x": float(x[k]),
                    "y": float(y[k]),
                    "heading": float(heading[k]),
                    "u": uk if math.isfinite(uk) else None,
                    "out": outs[i],
                    "root": root,
                    "expected_radius": R,
                    "radial_error": err,
                    **({} if follow is None else {"follow": str(FOLLOW_STATES[int(follow[k])])}),
                }
            )
        return {"tick": int(tick), "time": float(t), "agents": rows}

    # -- the scene ----------------------------------------------------------------------------
    def scene(self, ns: Any, ids: Any, x: Any, y: Any, out: Any, heading: Any, alive: Any, numbers: Any) -> Any:
        # lazy: foxglove (18 ms) only where a scene is drawn; readers of a run import this module (world/stream.py)
        from foxglove.messages import (
            ArrowPrimitive,
            Color,
            LinePrimitive,
            LinePrimitiveLineType,
            Point3,
            SceneEntity,
            SceneUpdate,
            SpherePrimitive,
            Vector3,
        )

        ts = _stamp(ns)
        red, blue, grey = (
            Color(r=0.85, g=0.15, b=0.15, a=1.0),
            Color(r=0.15, g=0.35, b=0.85, a=1.0),
            Color(r=0.4, g=0.4, b=0.4, a=0.8),
        )
        leader = self.leaders
        col = {int(i): k for k, i in enumerate(ids)}
        arrows, points = [], []
        for k in range(len(ids)):
            if not alive[k]:
                continue
            arrows.append(
                ArrowPrimitive(
                    pose=_pose(float(x[k]), float(y[k]), float(heading[k])),
                    shaft_length=3.0,
                    shaft_diameter=0.6,
                    head_length=1.5,
                    head_diameter=1.5,
                    color=red if int(ids[k]) in leader else blue,
                )
            )
            j = col.get(int(out[k]))
            if j is not None:
                points += [Point3(x=float(x[k]), y=float(y[k]), z=0.0), Point3(x=float(x[j]), y=float(y[j]), z=0.0)]
        tx, ty = self.target
        target = SpherePrimitive(
            pose=_pose(tx, ty, 0.0), size=Vector3(x=2.0, y=2.0, z=2.0), color=Color(r=0.1, g=0.1, b=0.1, a=1.0)
        )
        radii = tuple(sorted({round(r["expected_radius"], 3) for r in numbers["agents"] if r["expected_radius"]}))
        if radii != self.radii:  # the circles change only when the graph does
            orbit = Color(r=0.2, g=0.6, b=0.2, a=0.6)
            self.radii, self.circles = (
                radii,
                [
                    LinePrimitive(
                        type=LinePrimitiveLineType.LineLoop,
                        thickness=0.2,
                        color=orbit,
                        points=[
                            Point3(x=tx + R * math.cos(a), y=ty + R * math.sin(a), z=0.0)
                            for a in np.linspace(0.0, 2 * math.pi, ORBIT_POINTS, endpoint=False)
                        ],
                    )
                    for R in radii
                ],
            )
        circles = self.circles
        return SceneUpdate(
            entities=[
                SceneEntity(timestamp=ts, frame_id="world", id="agents", arrows=arrows),
                SceneEntity(
                    timestamp=ts,
                    frame_id="world",
                    id="edges",
                    lines=[
                        LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=0.3, points=points, color=grey)
                    ],
                ),
                SceneEntity(timestamp=ts, frame_id="world", id="target", spheres=[target]),
                SceneEntity(timestamp=ts, frame_id="world", id="orbits", lines=circles),
            ]
        )

    def trails_update(self, ns: Any, ids: Any, x: Any, y: Any, alive: Any) -> Any:
        """Sample the trails (every trail_every scene updates); a SceneUpdate of them every
        TRAIL_EVERY samples, else None."""
        self.updates += 1
        if self.updates % self.trail_every:
            return None
        for k, i in enumerate(ids):
            tr = self.trails.setdefault(int(i), deque(maxlen=self.trail_len))
            if alive[k]:
                tr.append((float(x[k]), float(y[k])))
        if (self.updates // self.trail_every) % TRAIL_EVERY != 1:
            return None
        # lazy: foxglove (18 ms) only where a scene is drawn; readers of a run import this module (world/stream.py)
        from foxglove.messages import Color, LinePrimitive, LinePrimitiveLineType, Point3, SceneEntity, SceneUpdate

        ts = _stamp(ns)
        leader = self.leaders
        lines = [
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                thickness=0.15,
                color=Color(r=0.85, g=0.4, b=0.4, a=0.6) if i in leader else Color(r=0.4, g=0.55, b=0.9, a=0.6),
                points=[Point3(x=px, y=py, z=0.0) for px, py in tr],
            )
            for i, tr in self.trails.items()
            if len(tr) > 1
        ]
        return SceneUpdate(entities=[SceneEntity(timestamp=ts, frame_id="world", id="trails", lines=lines)])


class SceneChannels:
    """The channels of what Foxglove shows of a run, in `ctx` (a foxglove.Context), in this
    order: `/swarm/events`, `/swarm/run`, `/swarm/scene`, `/swarm/agents`, `/swarm/trails`."""

    def __init__(self, ctx: Any, target: tuple[float, float], agents: Any, scene_rate: float) -> None:
        # lazy: foxglove (18 ms) only where a scene is drawn; readers of a run import this module (world/stream.py)
        import foxglove
        from foxglove.channels import SceneUpdateChannel

        def json_channel(topic: str, title: str) -> Any:
            return foxglove.Channel(topic, schema={"title": title, "type": "object"}, context=ctx)

        self.events_ch = json_channel("/swarm/events", "swarm.Event")
        self.run_ch = json_channel("/swarm/run", "swarm.Run")
        self.scene_ch = SceneUpdateChannel("/swarm/scene", context=ctx)
        self.agents_ch = json_channel("/swarm/agents", "swarm.Agents")
        self.trails_ch = SceneUpdateChannel("/swarm/trails", context=ctx)
        self.builder = SceneBuilder(target, agents, scene_rate)

    def run(self, msg: dict, t: float = 0.0) -> None:
        self.run_ch.log(msg, log_time=log_time(t))

    def add_agent(self, spec: Any, doc: dict, t: float) -> None:
        """An agent added at run time: drawn from now on, and `{"add_agent": doc}` on /swarm/run."""
        self.builder.add_agent(spec)
        self.run({"add_agent": doc}, t)

    def event(self, ev: dict) -> None:
        self.events_ch.log(json.loads(json.dumps(ev, default=_plain)), log_time=log_time(ev.get("time", 0.0)))

    def tick(
        self,
        tick: int,
        t: Any,
        ids: Any,
        x: Any,
        y: Any,
        heading: Any,
        u: Any,
        out: Any,
        alive: Any,
        follow: Any = None,
    ) -> None:
        """One scene update: the agents' numbers, the scene and, now and then, the trails."""
        ns = log_time(t)
        b = self.builder
        numbers = b.numbers(tick, t, ids, x, y, heading, u, out, alive, follow)
        self.agents_ch.log(numbers, log_time=ns)
        self.scene_ch.log(b.scene(ns, ids, x, y, out, heading, alive, numbers), log_time=ns)
        trails = b.trails_update(ns, ids, x, y, alive)
        if trails is not None:
            self.trails_ch.log(trails, log_time=ns)


def _plain(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o)}")


def _stamp(ns: int) -> Any:
    from foxglove.messages import Timestamp  # lazy: as in SceneChannels.scene

    return Timestamp(sec=ns // 10**9, nsec=ns % 10**9)


def _pose(x: float, y: float, h: float) -> Any:
    from foxglove.messages import Pose, Quaternion, Vector3  # lazy: as in SceneChannels.scene

    return Pose(
        position=Vector3(x=x, y=y, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=math.sin(h / 2), w=math.cos(h / 2))
    )
