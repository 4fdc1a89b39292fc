"""The lockstep job on zmq over ipc (see common.py): a world and N agents.

    python benchmarks/peers/zmq_peer.py world DIR --n N --k K --ticks T --result FILE
    python benchmarks/peers/zmq_peer.py agent DIR INDEX

The world binds a ROUTER socket (ipc://DIR/w) and a PUB socket for the truth (ipc://DIR/t,
nobody subscribes: as swarm's truth with no viewer); each agent connects a DEALER whose
identity is its index, says hello, then answers each frame from its main thread (a
blocking recv). The world starts when all N said hello.
"""

from __future__ import annotations

import sys
from pathlib import Path

import zmq

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.peers.common import END, TickTimeout, answer, lockstep, wait_release, world_args, write_result  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402


def world(d: str, argv: list[str]) -> int:
    a = world_args(argv, __doc__)
    ctx = zmq.Context()
    router = ctx.socket(zmq.ROUTER)
    router.setsockopt(zmq.SNDHWM, 0)
    router.setsockopt(zmq.RCVHWM, 0)
    router.bind(f"ipc://{d}/w")
    pub = ctx.socket(zmq.PUB)
    pub.bind(f"ipc://{d}/t")
    try:
        ids = [str(i).encode() for i in range(a.n)]
        seen: set[bytes] = set()
        router.setsockopt(zmq.RCVTIMEO, int(1000 * a.join_timeout))
        while len(seen) < a.n:
            try:
                ident, _ = router.recv_multipart()
            except zmq.Again:
                write_result(a.result, {"ok": False, "error": f"{len(seen)} of {a.n} agents said hello"})
                return ExitCode.FAILED
            seen.add(ident)
        poller = zmq.Poller()
        poller.register(router, zmq.POLLIN)
        router.setsockopt(zmq.RCVTIMEO, -1)

        def send(i: int, b: bytes | bytearray) -> None:
            router.send_multipart((ids[i], b))

        def next_answer(timeout: float) -> bytes | None:
            if not poller.poll(int(1000 * timeout)):
                return None
            return router.recv_multipart()[1]

        try:
            r = lockstep(a.n, a.k, a.ticks, a.warmup, send, pub.send, next_answer, a.measuring)
        except TickTimeout as e:
            write_result(a.result, {"ok": False, "error": str(e)})
            return ExitCode.FAILED
        write_result(a.result, r)
        wait_release(a.release)
        for i in ids:
            router.send_multipart((i, END))
        return ExitCode.OK
    finally:
        router.close(linger=1000)
        pub.close(linger=0)
        ctx.term()


def agent(d: str, index: int) -> int:
    ctx = zmq.Context()
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.IDENTITY, str(index).encode())
    s.setsockopt(zmq.RCVTIMEO, 600_000)
    s.connect(f"ipc://{d}/w")
    try:
        s.send(b"hello")
        while True:
            try:
                buf = s.recv()
            except zmq.Again:
                return ExitCode.FAILED
            if buf == END:
                return ExitCode.OK
            s.send(answer(buf))
    finally:
        s.close(linger=1000)
        ctx.term()


def main(argv: list[str]) -> int:
    if argv[0] == "world":
        return world(argv[1], argv[2:])
    return agent(argv[1], int(argv[2]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
