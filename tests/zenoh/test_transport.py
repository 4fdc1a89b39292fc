"""Two real zenoh sessions in one process on a Unix socket in the test's tmp dir: the hub and
client settings of swarm/contracts/transport.py carry the protocol's puts, liveliness and queries."""

from __future__ import annotations

import queue

import pytest
import zenoh
from deadlines import DEADLINE

from swarm.contracts import wire
from swarm.contracts.transport import open_client, open_hub, query_statuses
from swarm.contracts.vocabulary import Phase
from swarm.runtime.procs import wait_until

RUN = "two-sessions"


@pytest.fixture
def sessions(tmp_path):
    ep = f"unixsock-stream/{tmp_path / 'hub.sock'}"
    hub = open_hub(ep)
    try:
        client = open_client(ep, timeout_ms=3000)
    except Exception:
        hub.close()
        raise
    try:
        yield hub, client
    finally:
        client.close()
        hub.close()


def _get(q: queue.Queue, timeout: float = DEADLINE):
    return q.get(timeout=timeout)


def test_a_command_put_by_the_client_reaches_the_hub(sessions):
    hub, client = sessions
    got: queue.Queue = queue.Queue()
    sub = hub.declare_subscriber(
        wire.agent_key(RUN, "*", "cmd"), lambda s: got.put((str(s.key_expr), s.payload.to_bytes()))
    )
    try:
        cmd = wire.Command(4, 17, -0.25, 2, Phase.TRACK, 3, 77)

        def delivered():  # put again until the subscription has reached the client
            client.put(wire.agent_key(RUN, 4, "cmd"), wire.encode_cmd(cmd))
            try:
                return _get(got, 0.2)
            except queue.Empty:
                return None

        first = wait_until(delivered, DEADLINE, interval=0)
        if not first:
            pytest.fail(f"no command reached the hub within {DEADLINE:g} s")
        key, payload = first
        assert wire.agent_of_key(key) == 4 and wire.decode_cmd(payload) == cmd
    finally:
        sub.undeclare()


def test_liveliness_token_appears_and_goes(sessions):
    hub, client = sessions
    seen: queue.Queue = queue.Queue()

    sub = hub.liveliness().declare_subscriber(
        wire.agent_key(RUN, "*", "alive"),
        lambda s: seen.put((wire.agent_of_key(str(s.key_expr)), s.kind)),
        history=True,
    )
    try:
        token = client.liveliness().declare_token(wire.agent_key(RUN, 5, "alive"))
        assert _get(seen) == (5, zenoh.SampleKind.PUT)
        token.undeclare()
        assert _get(seen) == (5, zenoh.SampleKind.DELETE)
    finally:
        sub.undeclare()


def test_status_query_returns_each_agents_own_status(sessions):
    hub, client = sessions
    st = {"id": 3, "role": "follower", "out": 1, "hops": 1, "rooted": True}
    qa = client.declare_queryable(
        wire.agent_key(RUN, 3, "status"), lambda q: q.reply(wire.agent_key(RUN, 3, "status"), wire.encode_status(st))
    )
    liar = client.declare_queryable(
        wire.agent_key(RUN, 8, "status"),  # answers for another id: skipped
        lambda q: q.reply(wire.agent_key(RUN, 8, "status"), wire.encode_status(st)),
    )
    try:

        def answered():
            got = query_statuses(hub, RUN, timeout=1.0)
            return got if 3 in got else None

        got = wait_until(answered, DEADLINE, interval=0) or {}
        assert set(got) == {3} and got[3]["out"] == 1
    finally:
        qa.undeclare()
        liar.undeclare()
