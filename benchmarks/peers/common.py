"""What every peer of benchmarks/peers/ shares: the lockstep job's sizes, its world loop and
its result file (see run.py).

Per tick the world sends every agent its own frame of 52 + 30*K bytes (K contacts) and one
truth message of 24 + 41*N bytes (the sizes of swarm's sense and truth records,
swarm/contracts/wire.py), every agent answers 38 bytes (a cmd record), and the world starts
the next tick when all N have answered that tick. Nothing is computed: no physics, no
sensing, no law, no recording. A frame and an answer lead with (agent index, tick).
"""

from __future__ import annotations

import argparse
import json
import statistics
import struct
import time
from collections.abc import Callable
from pathlib import Path

HEAD = struct.Struct("<iq")  # agent index, tick: the first 12 bytes of a frame and of an answer
FRAME_HEAD_BYTES = 52
CONTACT_BYTES = 30
ANSWER_BYTES = 38
TRUTH_HEAD_BYTES = 24
TRUTH_RECORD_BYTES = 41
END = b"e"  # a frame of this one byte ends an agent


def frame_bytes(k: int) -> int:
    return FRAME_HEAD_BYTES + CONTACT_BYTES * k


def truth_bytes(n: int) -> int:
    return TRUTH_HEAD_BYTES + TRUTH_RECORD_BYTES * n


def frames(n: int, k: int) -> list[bytearray]:
    """One reusable frame buffer per agent (its index written once; the tick each tick)."""
    out = []
    for i in range(n):
        b = bytearray(frame_bytes(k))
        HEAD.pack_into(b, 0, i, 0)
        out.append(b)
    return out


def answer(frame: bytes | bytearray | memoryview) -> bytes:
    """An agent's 38-byte answer to a frame: its index and the frame's tick, then zeros."""
    i, tick = HEAD.unpack_from(frame, 0)
    return HEAD.pack(i, tick) + bytes(ANSWER_BYTES - HEAD.size)


class TickTimeout(Exception):
    pass


def lockstep(
    n: int,
    k: int,
    ticks: int,
    warmup: int,
    send: Callable[[int, bytes | bytearray], None],
    send_truth: Callable[[bytes], None],
    next_answer: Callable[[float], bytes | None],
    measuring: Path | None,
    tick_timeout: float = 10.0,
) -> dict:
    """The world's loop: `warmup` ticks, then `ticks` measured ones. send(i, frame) sends agent
    i its frame; next_answer(timeout) gives one answer (None on timeout). `measuring` is
    touched when the measured ticks start (run.py samples CPU from then on)."""
    bufs = frames(n, k)
    truth = bytearray(truth_bytes(n))
    pack_into, unpack_from = HEAD.pack_into, HEAD.unpack_from
    durations: list[float] = []
    t0 = time.perf_counter()
    for tick in range(warmup + ticks):
        if tick == warmup:
            if measuring is not None:
                measuring.touch()
            t0 = time.perf_counter()
        t_tick = time.perf_counter()
        for i in range(n):
            b = bufs[i]
            pack_into(b, 0, i, tick)
            send(i, b)
        pack_into(truth, 8, 0, tick)
        send_truth(bytes(truth))
        got = bytearray(n)
        pending = n
        deadline = time.monotonic() + tick_timeout
        while pending:
            left = deadline - time.monotonic()
            buf = next_answer(left) if left > 0 else None
            if buf is None:
                raise TickTimeout(f"tick {tick}: {pending} of {n} agents did not answer within {tick_timeout} s")
            i, t = unpack_from(buf, 0)
            if t == tick and 0 <= i < n and not got[i]:
                got[i] = 1
                pending -= 1
        if tick >= warmup:
            durations.append(time.perf_counter() - t_tick)
    wall = time.perf_counter() - t0
    durations.sort()
    return {
        "ok": True,
        "ticks": ticks,
        "wall_time": wall,
        "ticks_per_second": ticks / wall,
        "tick_ms_p50": 1e3 * statistics.median(durations),
        "tick_ms_p99": 1e3 * durations[min(len(durations) - 1, int(0.99 * len(durations)))],
        "frame_bytes": frame_bytes(k),
        "truth_bytes": truth_bytes(n),
    }


def write_result(path: Path, result: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(result) + "\n")
    tmp.replace(path)


def world_args(argv: list[str] | None, doc: str) -> argparse.Namespace:
    """The arguments every peer's world takes (run.py passes them)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--n", type=int, required=True, help="agents")
    ap.add_argument("--k", type=int, required=True, help="contacts per frame")
    ap.add_argument("--ticks", type=int, required=True, help="measured ticks")
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--result", type=Path, required=True, help="the result JSON is written here")
    ap.add_argument("--measuring", type=Path, help="touched when the measured ticks start")
    ap.add_argument("--join-timeout", type=float, default=60.0)
    ap.add_argument(
        "--release", type=Path, help="after the result, wait (up to 30 s) for this file before ending the agents"
    )
    return ap.parse_args(argv)


def wait_release(path: Path | None, timeout: float = 30.0) -> None:
    """Keep every process up after the result until run.py has sampled their CPU time."""
    end = time.monotonic() + timeout
    while path is not None and not path.exists() and time.monotonic() < end:
        time.sleep(0.01)
