"""The lockstep job on dora-rs with Python nodes (see common.py).

    python benchmarks/peers/dora_peer.py yaml DATAFLOW --n N --k K --ticks T --result FILE [--measuring FILE]
    dora run DATAFLOW          (what run.py does: no coordinator, the daemon in that process)

`yaml` writes the dataflow: a node `world` with outputs frame_<i> and truth, inputs
ack_<i> from node agent_<i>; N nodes agent_<i> with input frame (world/frame_<i>) and
output ack. Each node is this file run by this interpreter (`world` or `agent INDEX`). The
world's first frames go out when every node is up (dora starts none before all are ready);
it sends arrow arrays of uint8 built from the frame's bytes, the agents answer likewise.
"""

from __future__ import annotations

import json
import queue
import sys
import threading
from pathlib import Path

import numpy as np
import pyarrow as pa  # type: ignore[import-untyped]  # pyarrow ships no type information
from dora import Node

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.peers.common import END, TickTimeout, answer, lockstep, wait_release, world_args, write_result  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402

HERE = Path(__file__).resolve()


def dataflow(n: int, world_argv: list[str]) -> dict:
    py = sys.executable
    nodes: list[dict] = [
        {
            "id": "world",
            "path": py,
            "args": " ".join([str(HERE), "world", *world_argv]),
            "inputs": {f"ack_{i}": f"agent_{i}/ack" for i in range(n)},
            "outputs": [*(f"frame_{i}" for i in range(n)), "truth"],
        }
    ]
    nodes += [
        {
            "id": f"agent_{i}",
            "path": py,
            "args": f"{HERE} agent {i}",
            "inputs": {"frame": f"world/frame_{i}"},
            "outputs": ["ack"],
        }
        for i in range(n)
    ]
    return {"nodes": nodes}


def as_array(b: bytes | bytearray) -> pa.Array:
    return pa.array(np.frombuffer(bytes(b), dtype=np.uint8))


def world(argv: list[str]) -> int:
    a = world_args(argv, __doc__)
    node = Node()
    answers: queue.SimpleQueue = queue.SimpleQueue()

    def pump() -> None:  # dora's events on a thread: next_answer waits with a timeout
        for event in node:
            if event["type"] == "INPUT":
                answers.put(event["value"].to_numpy().tobytes())
            elif event["type"] == "STOP":
                break

    pumping = threading.Thread(target=pump, daemon=True)
    pumping.start()

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
            lambda i, b: node.send_output(f"frame_{i}", as_array(b)),
            lambda b: node.send_output("truth", as_array(b)),
            next_answer,
            a.measuring,
            # Each dora node also opens a zenoh peer session that scouts the others at the start;
            # at N = 50 on a loaded 2-core machine one early tick once took longer than 10 s.
            tick_timeout=60.0,
        )
    except TickTimeout as e:
        write_result(a.result, {"ok": False, "error": str(e)})
        return ExitCode.FAILED
    write_result(a.result, r)
    wait_release(a.release)
    for i in range(a.n):
        node.send_output(f"frame_{i}", as_array(END))
    pumping.join(timeout=30)  # until the agents' outputs closed: leaving earlier crashes the node
    return ExitCode.OK


def agent(index: int) -> int:
    node = Node()
    for event in node:
        if event["type"] == "INPUT":
            buf = event["value"].to_numpy().tobytes()
            if buf == END:
                return ExitCode.OK
            node.send_output("ack", as_array(answer(buf)))
        elif event["type"] == "STOP":
            return ExitCode.OK
    return ExitCode.OK


def main(argv: list[str]) -> int:
    if argv[0] == "yaml":
        a = world_args(argv[2:], __doc__)
        Path(argv[1]).write_text(json.dumps(dataflow(a.n, argv[2:]), indent=1))  # JSON is YAML
        return ExitCode.OK
    if argv[0] == "world":
        return world(argv[1:])
    return agent(int(argv[1]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
