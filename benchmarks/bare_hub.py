"""The hub of the bare-zenoh lockstep baseline: no physics, no law, no recording.

    python benchmarks/bare_hub.py --listen ENDPOINT --run RUN --n N --ticks T
                                  [--warmup W] [--join-timeout S] [--tick-timeout S] --result FILE
                                  [--ready FILE] [--linger S] [--handler callback|channel] [--creds FILE]

A router-mode session with swarm's own hub config (swarm.contracts.transport.hub_config). It
waits until N bare_client.py processes have declared their liveliness tokens, then per
tick sends one 8-byte message to each client on that client's own key and waits until
every client answered with one 12-byte message for that tick. The first W ticks warm
up; ticks/s is measured over the next T ticks. Callbacks only enqueue; the main thread
does the rest (the structure of world/process.py's lockstep loop). Writes one JSON
object to --result, lingers --linger s (so that the clients' memory can be sampled
undisturbed), ends the clients and exits 0; exits 2 when the clients did not all join
or a tick timed out.

With --creds (the run's own credentials file, with its secret) the hub checks who connects
and what they may do exactly as a world does (swarm.contracts.transport.open_hub with
HubAuth: usrpwd, access rules, size filters; clients are agents 0..N-1), on swarm's keys.
"""

from __future__ import annotations

import argparse
import json
import queue
import statistics
import sys
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bare_client import ACK, TICK, _key  # noqa: E402
from swarm.contracts import credentials  # noqa: E402
from swarm.contracts.transport import HubAuth, open_hub  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402

CLIENTS_LATE = 2  # this bare hub's own exit code: clients did not join, or answer, in time


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--listen", required=True)
    ap.add_argument("--run", required=True)
    ap.add_argument("--n", type=int, required=True)
    ap.add_argument("--ticks", type=int, required=True)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--join-timeout", type=float, default=90.0)
    ap.add_argument("--tick-timeout", type=float, default=5.0)
    ap.add_argument("--result", required=True)
    ap.add_argument("--ready", help="touch this file when every client joined (ticking starts)")
    ap.add_argument(
        "--linger",
        type=float,
        default=0.0,
        help="s to wait after writing the result before ending the clients (to sample their memory)",
    )
    ap.add_argument(
        "--handler",
        choices=("callback", "channel"),
        default="callback",
        help="callback: Python callback enqueues (like world/process.py); "
        "channel: zenoh's FIFO channel, the main thread blocks in recv() (no tick timeout)",
    )
    ap.add_argument("--creds", help="the run's credentials file: check clients as a world does")
    a = ap.parse_args(argv)

    auth = HubAuth(credentials.read(Path(a.creds)), tuple(range(a.n))) if a.creds else None

    def key(run, index, leaf):
        return _key(run, index, leaf, auth is not None)

    t_start = time.monotonic()
    acks: queue.SimpleQueue = queue.SimpleQueue()
    joins: queue.SimpleQueue = queue.SimpleQueue()
    result: dict = {"n": a.n, "ticks": a.ticks, "warmup": a.warmup, "handler": a.handler, "ok": False}
    session = open_hub(a.listen, auth)
    try:
        if a.handler == "channel":
            ack_sub = session.declare_subscriber(key(a.run, "*", "ack"))

            def next_ack(timeout: float) -> bytes:
                return ack_sub.recv().payload.to_bytes()
        else:
            ack_sub = session.declare_subscriber(key(a.run, "*", "ack"), lambda s: acks.put(s.payload.to_bytes()))

            def next_ack(timeout: float) -> bytes:
                return acks.get(timeout=timeout)

        subs = [  # noqa: F841 (kept alive until close)
            session.liveliness().declare_subscriber(
                key(a.run, "*", "alive"),
                lambda s: joins.put((str(s.key_expr), s.kind == zenoh.SampleKind.PUT)),
                history=True,
            ),
        ]
        pubs = [session.declare_publisher(key(a.run, i, "tick"), express=True) for i in range(a.n)]
        end = session.declare_publisher(key(a.run, None, "end"))

        # -- wait for every client's token ------------------------------------------------
        alive: set[str] = set()
        t_end = time.monotonic() + a.join_timeout
        while len(alive) < a.n:
            left = t_end - time.monotonic()
            if left <= 0:
                result["error"] = f"only {len(alive)} of {a.n} clients joined within {a.join_timeout} s"
                return CLIENTS_LATE
            try:
                k, put = joins.get(timeout=left)
            except queue.Empty:
                continue
            (alive.add if put else alive.discard)(k)
        result["join_s"] = time.monotonic() - t_start
        if a.ready:
            Path(a.ready).touch()

        # -- lockstep ----------------------------------------------------------------------
        n, pack, unpack = a.n, TICK.pack, ACK.unpack
        durations: list[float] = []
        total = a.warmup + a.ticks
        t0 = time.perf_counter()
        for tick in range(total):
            if tick == a.warmup:
                t0 = time.perf_counter()
            t_tick = time.perf_counter()
            msg = pack(tick)
            for p in pubs:
                p.put(msg)
            got = bytearray(n)
            pending = n
            deadline = time.monotonic() + a.tick_timeout
            while pending:
                left = deadline - time.monotonic()
                if left <= 0:
                    result["error"] = f"tick {tick}: {pending} of {n} clients did not answer within {a.tick_timeout} s"
                    return CLIENTS_LATE
                try:
                    buf = next_ack(left)
                except queue.Empty:
                    continue
                i, t = unpack(buf)
                if t == tick and 0 <= i < n and not got[i]:
                    got[i] = 1
                    pending -= 1
            if tick >= a.warmup:
                durations.append(time.perf_counter() - t_tick)
        wall = time.perf_counter() - t0
        durations.sort()
        result.update(
            ok=True,
            wall_time=wall,
            ticks_per_second=a.ticks / wall,
            tick_ms_p50=1e3 * statistics.median(durations),
            tick_ms_p99=1e3 * durations[min(len(durations) - 1, int(0.99 * len(durations)))],
            tick_ms_max=1e3 * durations[-1],
        )
        write(a.result, result)
        time.sleep(a.linger)
        for p in pubs:
            p.put(b"e")
        end.put(b"end")
        time.sleep(0.05)  # let the end message leave before the socket closes
        return ExitCode.OK
    finally:
        session.close()
        if not Path(a.result).exists():
            write(a.result, result)


def write(path: str, result: dict) -> None:
    tmp = Path(path + ".tmp")
    tmp.write_text(json.dumps(result) + "\n")
    tmp.replace(path)


if __name__ == "__main__":
    sys.exit(main())
