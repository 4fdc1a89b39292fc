"""Ablations for benchmarks/bench_ablation.py (a benchmark, never the product).

bench_ablation.py puts this directory first on PYTHONPATH, so every Python process of the
`swarm up` it starts (launcher, world, fork server, agents) imports this file at start-up.
With SWARM_ABLATE unset it does nothing. Otherwise it takes work out of the lockstep tick,
to show what each part of that work costs against the bare-zenoh floor:

- "agents": an agent answers each frame without deciding anything: it reads the tick from
  the frame's header and sends a fixed command (leaders: their orbit rate, followers:
  C2, a loitering circle), with no decoding of contacts, no selection and no law;
- "world": after its first frames the world sends the same frames again (tick and time
  patched into the header), records nothing and does not integrate: no sensing, no frame
  encoding, no recording, no physics, no ground truth for observers (the whole end of the
  tick is skipped); commands are still received, checked and latched. Agents that join
  later get no frames (the benchmark's agents all join before the first tick);
- "both": the two;
- "recording": the world writes no recording (everything else as shipped).

The messaging, the processes and the world's handling of commands are the product's own.
Being first on PYTHONPATH, this file hides any other sitecustomize of the environment for
those processes (a benchmark's price: nothing else here needs one).
"""

from __future__ import annotations

import os
import struct

MODE = os.environ.get("SWARM_ABLATE", "")
TICK_AT = struct.calcsize("<BBBBi")  # where a frame's tick is (wire.SENSE_HEAD: kind, version, has_target,
# reserved, agent; tick)


def _null_agents() -> None:
    # lazy: this file runs at every Python start-up here; swarm only once an ablation is asked for
    from swarm.agents.node import AgentNode
    from swarm.contracts import wire
    from swarm.contracts.vocabulary import Phase

    tick_of = struct.Struct("<q").unpack_from

    def on_sense_sample(self, sample) -> None:
        payload = sample.payload.to_bytes()
        tick = tick_of(payload, TICK_AT)[0]
        spec = self.spec
        if spec.role == "leader":
            u, phase, hops = spec.speed / spec.orbit_radius * spec.direction_sign, Phase.ORBIT, 0
        else:
            u, phase, hops = self.conf.gains.c2, Phase.LOST, None
        self.cmd_pub.put(wire.encode_cmd_fields(self.id, tick, u, None, phase, hops, self.key))

    AgentNode.on_sense_sample = on_sense_sample


def _frozen_world() -> None:
    from swarm.world.process import World  # lazy: (as in _null_agents)

    patch = struct.Struct("<qd").pack_into
    real_publish = World.publish_frames

    def publish_frames(self) -> set[int]:
        cache = getattr(self, "_ablation_frames", None)
        if cache is None:
            sent: dict[int, bytes] = {}
            pubs = self.sense_pub
            self.sense_pub = {aid: _Capture(p, aid, sent) for aid, p in pubs.items()}
            try:
                active = real_publish(self)
            finally:
                self.sense_pub = pubs
            self._ablation_frames = sent
            return active
        c = self.core
        for aid, frame in cache.items():
            buf = bytearray(frame)
            patch(buf, TICK_AT, c.tick, c.time)
            self.sense_pub[aid].put(bytes(buf))
        return set(cache)

    def record_and_step(self) -> None:
        self.core.tick += 1

    World.publish_frames = publish_frames
    World.record_and_step = record_and_step


class _Capture:
    def __init__(self, pub, aid: int, sent: dict):
        self.pub, self.aid, self.sent = pub, aid, sent

    def put(self, payload: bytes) -> None:
        self.sent[self.aid] = payload
        self.pub.put(payload)


def _no_recording() -> None:
    from swarm.world.recording import DeferredRecorder  # lazy: (as in _null_agents)

    DeferredRecorder.record = lambda self, *args, **kwargs: None


if MODE in ("agents", "both"):
    _null_agents()
if MODE in ("world", "both"):
    _frozen_world()
if MODE == "recording":
    _no_recording()
