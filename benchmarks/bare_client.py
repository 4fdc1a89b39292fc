"""One client of the bare-zenoh lockstep baseline (see bare_hub.py).

    python benchmarks/bare_client.py INDEX ENDPOINT RUN [--timeout S] [--creds FILE]

Connects to the hub as a zenoh client (swarm.contracts.transport.client_config, like an agent),
subscribes to its own tick key, declares a liveliness token (how the hub knows it is
ready) and answers each tick with one small message on its own ack key. The callback
only enqueues; the main thread publishes (the same structure as agents/process.py,
without decoding, law or status traffic). Exits on the hub's end message, or after
--timeout seconds whatever happens.

With --creds (a run's credentials file, see swarm/contracts/credentials.py) it connects as
`agent-<INDEX>` and uses swarm's own keys (frames on agent/<i>/sense, answers on
agent/<i>/cmd, its token on agent/<i>/alive, the end on world/control), so that a hub
with swarm's access rules lets it through: the cost of the hub's checks, measured bare.
"""

from __future__ import annotations

import argparse
import queue
import struct
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from swarm.contracts import credentials, wire  # noqa: E402
from swarm.contracts.transport import open_client  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402

TICK = struct.Struct("<q")  # tick
ACK = struct.Struct("<iq")  # client index, tick


def _key(run: str, index: int | str | None, leaf: str, swarm_keys: bool = False) -> str:
    if swarm_keys:
        if leaf == "end":
            return wire.world_control_key(run)
        return wire.agent_key(run, index, {"tick": "sense", "ack": "cmd"}.get(leaf, leaf))
    return f"bench/{run}/c/{index}/{leaf}" if leaf != "end" else f"bench/{run}/end"


def key(run: str, index: int | str, leaf: str) -> str:
    return _key(run, index, leaf)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("index", type=int)
    ap.add_argument("endpoint")
    ap.add_argument("run")
    ap.add_argument("--timeout", type=float, default=300.0, help="exit after this many s in any case")
    ap.add_argument(
        "--handler",
        choices=("callback", "channel", "direct"),
        default="callback",
        help="callback: Python callback enqueues, the main thread answers; "
        "channel: zenoh's FIFO channel, the main thread blocks in recv(); "
        "direct: the callback answers (like agents/process.py)",
    )
    ap.add_argument("--creds", help="a run's credentials file: connect as agent-INDEX on swarm's keys")
    a = ap.parse_args(argv)

    deadline = time.monotonic() + a.timeout
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    put = inbox.put
    creds = credentials.read(Path(a.creds)) if a.creds else None
    sk = creds is not None

    def key(run, index, leaf):
        return _key(run, index, leaf, sk)

    session = open_client(a.endpoint, creds=creds, user=credentials.agent_user(a.index))
    try:
        ack = session.declare_publisher(key(a.run, a.index, "ack"), express=True)
        me = a.index
        pack, unpack = ACK.pack, TICK.unpack
        if a.handler == "channel":
            # The hub ends with a 1-byte message on every tick key: one blocking recv() per tick.
            sub = session.declare_subscriber(key(a.run, a.index, "tick"))
            token = session.liveliness().declare_token(key(a.run, a.index, "alive"))  # noqa: F841
            while time.monotonic() < deadline:
                buf = sub.recv().payload.to_bytes()
                if len(buf) != TICK.size:
                    break
                (tick,) = unpack(buf)
                ack.put(pack(me, tick))
            return ExitCode.OK
        if a.handler == "direct":
            done = queue.SimpleQueue()

            def on_tick(s):
                buf = s.payload.to_bytes()
                if len(buf) != TICK.size:
                    done.put(None)
                    return
                ack.put(pack(me, unpack(buf)[0]))

            subs = [  # noqa: F841 (kept alive until close)
                session.declare_subscriber(key(a.run, a.index, "tick"), on_tick),
                session.declare_subscriber(key(a.run, None, "end"), lambda s: done.put(None)),
            ]
            token = session.liveliness().declare_token(key(a.run, a.index, "alive"))  # noqa: F841
            try:
                done.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                pass
            return ExitCode.OK
        subs = [  # noqa: F841 (kept alive until close)
            session.declare_subscriber(key(a.run, a.index, "tick"), lambda s: put(s.payload.to_bytes())),
            session.declare_subscriber(key(a.run, None, "end"), lambda s: put(None)),
        ]
        token = session.liveliness().declare_token(key(a.run, a.index, "alive"))  # noqa: F841
        while time.monotonic() < deadline:
            try:
                item = inbox.get(timeout=1.0)
            except queue.Empty:
                continue
            if item is None or len(item) != TICK.size:
                break
            (tick,) = unpack(item)
            ack.put(pack(me, tick))
    finally:
        session.close()
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
