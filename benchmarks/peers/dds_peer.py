"""The lockstep job on Cyclone DDS through its Python binding (see common.py).

    python benchmarks/peers/dds_peer.py world --n N --k K --ticks T --result FILE
    python benchmarks/peers/dds_peer.py agent INDEX

One topic per agent for its frames (peers_frame_<i>), one for every answer (peers_ack), one
for the truth (nobody reads it); reliable, keep-all. A message is (agent, tick, bytes): the
index and tick as fields, the rest of the frame's or answer's bytes as a sequence of octets,
so that the sizes on the wire are those of the other peers. The world starts when every
frame writer has matched its reader and the answer reader has matched N writers. Both
sides wait in a WaitSet and take what arrived.
"""

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32, int64, sequence, uint8
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.peers.common import (  # noqa: E402
    ANSWER_BYTES,
    HEAD,
    TickTimeout,
    lockstep,
    wait_release,
    world_args,
    write_result,
)
from swarm.contracts.vocabulary import ExitCode  # noqa: E402


@dataclass
class Msg(IdlStruct, typename="peers.Msg"):
    agent: int32
    tick: int64
    data: sequence[uint8]  # type: ignore[type-arg]  # cyclonedds' IDL marker, subscripted by design


def msg(agent: int, tick: int, data: bytes) -> Msg:
    return Msg(agent, tick, data)  # type: ignore[arg-type]  # an IDL sequence[uint8] field takes bytes


QOS = Qos(Policy.Reliability.Reliable(duration(seconds=10)), Policy.History.KeepAll)
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
END_TICK = -1


def waiter(dp: DomainParticipant, reader: DataReader) -> WaitSet:
    ws = WaitSet(dp)
    ws.attach(ReadCondition(reader, ANY))
    return ws


def world(argv: list[str]) -> int:
    a = world_args(argv, __doc__)
    dp = DomainParticipant()
    writers = [DataWriter(dp, Topic(dp, f"peers_frame_{i}", Msg), qos=QOS) for i in range(a.n)]
    truth = DataWriter(dp, Topic(dp, "peers_truth", Msg), qos=QOS)
    acks = DataReader(dp, Topic(dp, "peers_ack", Msg), qos=QOS)
    ws = waiter(dp, acks)
    deadline = time.monotonic() + a.join_timeout
    while not (
        all(w.get_publication_matched_status().current_count >= 1 for w in writers)
        and acks.get_subscription_matched_status().current_count >= a.n
    ):
        if time.monotonic() > deadline:
            write_result(a.result, {"ok": False, "error": "agents not matched in time"})
            return ExitCode.FAILED
        time.sleep(0.05)
    buffered: list[bytes] = []

    def send(i: int, b: bytes | bytearray) -> None:
        writers[i].write(msg(i, HEAD.unpack_from(b, 0)[1], bytes(b[HEAD.size :])))

    def send_truth(b: bytes) -> None:
        truth.write(msg(-1, 0, b))

    def next_answer(timeout: float) -> bytes | None:
        if not buffered:
            end = time.monotonic() + timeout
            while not buffered:
                left = end - time.monotonic()
                if left <= 0:
                    return None
                ws.wait(duration(seconds=left))
                buffered.extend(HEAD.pack(m.agent, m.tick) for m in acks.take(N=256))
        return buffered.pop(0)

    try:
        r = lockstep(a.n, a.k, a.ticks, a.warmup, send, send_truth, next_answer, a.measuring)
    except TickTimeout as e:
        write_result(a.result, {"ok": False, "error": str(e)})
        return ExitCode.FAILED
    write_result(a.result, r)
    wait_release(a.release)
    for i, w in enumerate(writers):
        w.write(msg(i, END_TICK, b""))
    time.sleep(0.5)  # reliable delivery of the end before the participant goes
    return ExitCode.OK


def agent(index: int) -> int:
    dp = DomainParticipant()
    frames = DataReader(dp, Topic(dp, f"peers_frame_{index}", Msg), qos=QOS)
    ack = DataWriter(dp, Topic(dp, "peers_ack", Msg), qos=QOS)
    ws = waiter(dp, frames)
    rest = bytes(ANSWER_BYTES - HEAD.size)
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        ws.wait(duration(seconds=1))
        for m in frames.take(N=16):
            if m.tick == END_TICK:
                return ExitCode.OK
            ack.write(msg(index, m.tick, rest))
    return ExitCode.FAILED


def main(argv: list[str]) -> int:
    if argv[0] == "world":
        return world(argv[1:])
    return agent(int(argv[1]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
