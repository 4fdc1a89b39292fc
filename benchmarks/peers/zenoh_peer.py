"""The lockstep job on bare zenoh (see common.py): a world and N agents, no runtime.

    python benchmarks/peers/zenoh_peer.py world ENDPOINT --n N --k K --ticks T --result FILE
    python benchmarks/peers/zenoh_peer.py agent ENDPOINT INDEX

The world is a zenoh router listening on ENDPOINT with swarm's own hub configuration
(swarm.contracts.transport.hub_config), each agent a client with swarm's client
configuration: the same transport `swarm up` uses, without the runtime. An agent declares a
liveliness token when it subscribed (how the world knows it is there) and answers each
frame from its zenoh callback, as swarm's agents do. The world's callbacks only enqueue.
"""

from __future__ import annotations

import queue
import sys
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.peers.common import END, TickTimeout, answer, lockstep, wait_release, world_args, write_result  # noqa: E402
from swarm.contracts.transport import open_client, open_hub  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402


def key(index: int | str, leaf: str) -> str:
    return f"peers/agent/{index}/{leaf}"


def world(endpoint: str, argv: list[str]) -> int:
    a = world_args(argv, __doc__)
    answers: queue.SimpleQueue = queue.SimpleQueue()
    joins: queue.SimpleQueue = queue.SimpleQueue()
    session = open_hub(endpoint)
    try:
        sub = session.declare_subscriber(key("*", "ack"), lambda s: answers.put(s.payload.to_bytes()))  # noqa: F841
        tokens = session.liveliness().declare_subscriber(  # noqa: F841
            key("*", "alive"), lambda s: joins.put((str(s.key_expr), s.kind == zenoh.SampleKind.PUT)), history=True
        )
        pubs = [session.declare_publisher(key(i, "frame"), express=True) for i in range(a.n)]
        truth = session.declare_publisher("peers/truth", express=True)
        alive: set[str] = set()
        while len(alive) < a.n:
            try:
                k, put = joins.get(timeout=a.join_timeout)
            except queue.Empty:
                write_result(a.result, {"ok": False, "error": f"{len(alive)} of {a.n} agents joined"})
                return ExitCode.FAILED
            (alive.add if put else alive.discard)(k)

        def next_answer(timeout: float) -> bytes | None:
            try:
                return answers.get(timeout=timeout)
            except queue.Empty:
                return None

        try:
            r = lockstep(
                a.n,
                a.k,
                a.ticks,
                a.warmup,
                lambda i, b: pubs[i].put(bytes(b)),
                truth.put,
                next_answer,
                a.measuring,
            )
        except TickTimeout as e:
            write_result(a.result, {"ok": False, "error": str(e)})
            return ExitCode.FAILED
        write_result(a.result, r)
        wait_release(a.release)
        for p in pubs:
            p.put(END)
        return ExitCode.OK
    finally:
        session.close()


def agent(endpoint: str, index: int) -> int:
    done: queue.SimpleQueue = queue.SimpleQueue()
    session = open_client(endpoint)
    try:
        ack = session.declare_publisher(key(index, "ack"), express=True)

        def on_frame(s: zenoh.Sample) -> None:
            buf = s.payload.to_bytes()
            if buf == END:
                done.put(None)
            else:
                ack.put(answer(buf))

        sub = session.declare_subscriber(key(index, "frame"), on_frame)  # noqa: F841
        token = session.liveliness().declare_token(key(index, "alive"))  # noqa: F841
        try:
            done.get(timeout=600)
        except queue.Empty:
            return ExitCode.FAILED
        return ExitCode.OK
    finally:
        session.close()


def main(argv: list[str]) -> int:
    if argv[0] == "world":
        return world(argv[1], argv[2:])
    return agent(argv[1], int(argv[2]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
