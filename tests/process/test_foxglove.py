"""The Foxglove side of a run: the recording's topics, and `--foxglove`, the live view served
over Foxglove's WebSocket protocol by the world (world/live_view.py) or by an observer of a
live run (`swarm watch --foxglove`, swarm/live/foxglove.py), watched by a real WebSocket
client (a minimal one, standard library only, below); `--foxglove [PORT]` (swarm/cli/main.py)."""

from __future__ import annotations

import base64
import json
import os
import re
import signal
import socket
import struct
import time
from pathlib import Path

import pytest
from deadlines import DEADLINE
from typer.testing import CliRunner

from swarm.cli.main import app, foxglove_argv
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.world.live_view import LIVE_TOPICS, LiveViewError, start_live_view

REPO = Path(__file__).resolve().parents[2]
CASE2 = REPO / "scenarios" / "case2.toml"
RECORDED = {"/swarm/ticks", "/swarm/scene", "/swarm/trails", "/swarm/agents", "/swarm/events", "/swarm/run"}


def busy_port() -> tuple[socket.socket, int]:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s, s.getsockname()[1]


def free_port() -> int:
    s, port = busy_port()
    s.close()
    return port


@pytest.mark.slow
def test_recording_lists_the_topics(tmp_path):
    from mcap.reader import make_reader

    from swarm.offline.sim import run_sim

    path = tmp_path / "recording.mcap"
    run_sim(load_scenario(CASE2), 6.0, None, path)  # long enough for a trails message
    with open(path, "rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        assert topics == RECORDED
        agents = [json.loads(m.data) for _, c, m in reader.iter_messages(topics=["/swarm/agents"])]
    ids = {a.id for a in load_scenario(CASE2).agents}
    last = {r["id"]: r for r in agents[-1]["agents"]}
    assert set(last) == ids
    assert all(isinstance(r["radial_error"], float) for r in last.values()), last  # case2: every agent has a root
    assert all(r["u"] is None for r in last.values())  # the final state: no command
    # the follow states: none for the leaders, case2's sticky followers keep theirs by 6 s
    assert {i: r["follow"] for i, r in last.items()} == {
        a.id: "none" if a.role == "leader" else "keep" for a in load_scenario(CASE2).agents
    }
    assert all(isinstance(r["u"], float) for r in agents[-2]["agents"])


@pytest.mark.slow
def test_port_in_use_is_one_line():
    held, port = busy_port()
    try:
        for cmd in (
            ["up", str(CASE2), "--foxglove", "--foxglove-port", str(port)],
            ["world", str(CASE2), "--out", "/nonexistent/never", "--foxglove", "--foxglove-port", str(port)],
        ):
            res = CliRunner().invoke(app, cmd)
            assert res.exit_code == ExitCode.USAGE, res.output
            lines = res.output.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("--foxglove: cannot serve on 127.0.0.1:"), res.output
        res = CliRunner().invoke(app, ["world", str(CASE2), "--foxglove"])
        assert res.exit_code == ExitCode.USAGE and "--foxglove needs --out" in res.output
    finally:
        held.close()


def test_world_bind_failure_is_one_line(tmp_path):
    from swarm.world.stream import StreamWriter

    held, port = busy_port()
    w = StreamWriter(tmp_path / "r.mcap", load_scenario(CASE2), 10)
    try:
        with pytest.raises(LiveViewError) as e:
            start_live_view(w, "r", "127.0.0.1", port)
        assert "\n" not in str(e.value) and f"127.0.0.1:{port}" in str(e.value)
    finally:
        held.close()
        w.close()


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["up", "s.toml", "--foxglove"], ["up", "s.toml", "--foxglove"]),
        (["up", "s.toml", "--foxglove", "9000"], ["up", "s.toml", "--foxglove", "--foxglove-port", "9000"]),
        (["world", "--foxglove=9001", "s.toml"], ["world", "--foxglove", "--foxglove-port", "9001", "s.toml"]),
        (["watch", "--foxglove", "--run", "r"], ["watch", "--foxglove", "--run", "r"]),
        (["watch", "--foxglove", "--foxglove-port", "9"], ["watch", "--foxglove", "--foxglove-port", "9"]),
        (["watch", "--foxglove=x"], ["watch", "--foxglove=x"]),  # typer says what is wrong
        (["up", "s.toml", "--", "--foxglove", "9"], ["up", "s.toml", "--", "--foxglove", "9"]),
        (["sim", "s.toml", "--foxglove", "9"], ["sim", "s.toml", "--foxglove", "9"]),  # not a live-view command
        ([], []),
    ],
)
def test_foxglove_takes_an_optional_port(argv, expected):
    assert foxglove_argv(["swarm", *argv]) == ["swarm", *expected]


def test_the_world_stops_before_listening_when_the_port_is_in_use(tmp_path, monkeypatch, capsys):
    """world/main.py's own check (after `swarm world`'s): one line, exit 2, no recording left,
    and nothing listened on the endpoint."""
    from swarm.world.main import run_world
    from swarm.world.process import WorldConfig

    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(tmp_path / "rt"))
    held, port = busy_port()
    listen = f"unixsock-stream/{tmp_path / 'w.sock'}"
    try:
        code = run_world(
            WorldConfig(load_scenario(CASE2), "fg-busy", listen, tmp_path / "out", foxglove=("127.0.0.1", port))
        )
    finally:
        held.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [
        f"swarm world: --foxglove: cannot serve on 127.0.0.1:{port}: Address already in use"
    ], err
    assert not (tmp_path / "w.sock").exists() and not (tmp_path / "out" / "recording.mcap").exists()


# --- a minimal WebSocket client (RFC 6455), enough for the Foxglove protocol ------------------
# The protocol's subprotocol names: `foxglove.websocket.v1` as published, `foxglove.sdk.v1` as
# foxglove-sdk's server (0.30) names the same protocol (it accepts only that one); a client
# offers both, as the Foxglove app does, and the server picks one.
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")


class WsClient:
    def __init__(self, port: int, subprotocols=SUBPROTOCOLS, timeout: float = DEADLINE):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                f"Sec-WebSocket-Protocol: {', '.join(subprotocols)}\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            head += chunk
        head, self.buf = head.split(b"\r\n\r\n", 1)
        text = head.decode("latin-1")
        assert text.startswith("HTTP/1.1 101"), text
        picked = [
            ln.split(":", 1)[1].strip() for ln in text.split("\r\n") if ln.lower().startswith("sec-websocket-protocol:")
        ]
        assert picked and picked[0] in subprotocols, text
        self.subprotocol = picked[0]

    def _read(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("the server closed the connection")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def _send(self, opcode: int, payload: bytes) -> None:
        mask = os.urandom(4)
        n = len(payload)
        head = bytes([0x80 | opcode]) + (
            bytes([0x80 | n])
            if n < 126
            else bytes([0x80 | 126]) + struct.pack(">H", n)
            if n < 65536
            else bytes([0x80 | 127]) + struct.pack(">Q", n)
        )
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def send_json(self, msg: dict) -> None:
        self._send(0x1, json.dumps(msg).encode())

    def recv(self) -> str | bytes:
        """The next text (str) or binary (bytes) message; answers pings."""
        data, first = b"", None
        while True:
            b0, b1 = self._read(2)
            opcode, n = b0 & 0x0F, b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            payload = self._read(n)
            if opcode == 0x9:
                self._send(0xA, payload)
                continue
            if opcode == 0x8:
                raise ConnectionError("the server closed the connection")
            if opcode in (0x1, 0x2):
                first = opcode
            data += payload
            if b0 & 0x80:
                return data.decode() if first == 0x1 else data

    def close(self) -> None:
        self.sock.close()


def connect(port: int, timeout: float, check) -> WsClient:
    end = time.monotonic() + timeout
    while True:
        check()
        try:
            return WsClient(port)
        except OSError:
            if time.monotonic() > end:
                raise AssertionError(f"nothing served ws://127.0.0.1:{port} within {timeout} s") from None
            time.sleep(0.1)


@pytest.mark.slow
def test_up_serves_the_run_live(rt, tmp_path):
    from runtime_helpers import start_up

    port = free_port()
    up = start_up(
        rt.tracker,
        CASE2,
        tmp_path / "run",
        "--clock",
        "realtime",
        "--duration",
        "60",
        "--foxglove",
        "--foxglove-port",
        port,
    )
    try:
        ws = connect(port, 60, lambda: up.running("the live view"))
    except BaseException:
        os.kill(up.launcher.pid, signal.SIGINT)
        up.launcher.wait(DEADLINE)
        raise
    try:
        channels = {}
        while not channels:
            msg = ws.recv()
            if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                channels = {c["topic"]: c for c in json.loads(msg)["channels"]}
        assert set(channels) == set(LIVE_TOPICS), channels  # /swarm/ticks is not served
        assert channels["/swarm/agents"]["encoding"] == "json"
        assert channels["/swarm/scene"]["schemaName"] == "foxglove.SceneUpdate"
        subs = {1: "/swarm/agents", 2: "/swarm/scene"}
        ws.send_json(
            {"op": "subscribe", "subscriptions": [{"id": k, "channelId": channels[t]["id"]} for k, t in subs.items()]}
        )
        ids = {a.id for a in load_scenario(CASE2).agents}
        seen: set[int] = set()
        got_scene = False
        end = time.monotonic() + DEADLINE
        while not (seen == ids and got_scene):
            assert time.monotonic() < end, f"poses seen of {sorted(seen)} only; scene: {got_scene}"
            msg = ws.recv()
            if isinstance(msg, str) or msg[0] != 0x01:  # text ops, or not a message data frame
                continue
            sub, _ts = struct.unpack_from("<IQ", msg, 1)
            payload = msg[13:]
            if subs.get(sub) == "/swarm/agents":
                for row in json.loads(payload)["agents"]:
                    if row["alive"] and isinstance(row["x"], float) and isinstance(row["y"], float):
                        seen.add(row["id"])
            elif subs.get(sub) == "/swarm/scene":
                got_scene = got_scene or len(payload) > 0
    finally:
        ws.close()
        os.kill(up.launcher.pid, signal.SIGINT)
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    assert f"ws://127.0.0.1:{port}" in up.launcher.text()
    assert (tmp_path / "run" / "summary.json").exists()


def advertised(ws: WsClient) -> dict[str, dict]:
    """The channels of the server's first `advertise`, by topic."""
    while True:
        msg = ws.recv()
        if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
            return {c["topic"]: c for c in json.loads(msg)["channels"]}


def messages(ws: WsClient, subs: dict[int, str]):
    """(topic, JSON document or raw bytes) of each message data frame of these subscriptions."""
    while True:
        msg = ws.recv()
        if isinstance(msg, str) or msg[0] != 0x01:  # text ops, or not a message data frame
            continue
        sub, _ts = struct.unpack_from("<IQ", msg, 1)
        topic = subs.get(sub)
        yield topic, (msg[13:] if topic in ("/swarm/scene", "/swarm/trails") else json.loads(msg[13:]))


@pytest.mark.slow
def test_up_port_in_use_stops_at_once(rt, tmp_path):
    """`swarm up --foxglove PORT` (the port given as the option's value) with PORT taken: one
    line naming it, exit 2, nothing started."""
    from runtime_helpers import start_up

    held, port = busy_port()
    try:
        up = start_up(rt.tracker, CASE2, tmp_path / "run", "--foxglove", port)
        rc = up.launcher.wait(DEADLINE)
    finally:
        held.close()
    rt.tracker.assert_none_left(timeout=DEADLINE)
    lines = up.launcher.text().strip().splitlines()
    assert rc == 2 and lines == [f"--foxglove: cannot serve on 127.0.0.1:{port}: Address already in use"], lines


@pytest.mark.slow
def test_watch_serves_a_live_run(rt, tmp_path):
    """`swarm watch --foxglove PORT` attached to a `swarm up`: the topics of the world's live
    view, every agent's pose, the drop of a killed agent on /swarm/events; a port in use is one
    line and exit 2; Ctrl-C exits 130 and leaves nothing running."""
    from runtime_helpers import start_up, swarm_cmd

    up = start_up(rt.tracker, CASE2, tmp_path / "run", "--clock", "realtime", "--duration", "120")
    up.wait_started(DEADLINE)
    held, busy = busy_port()
    try:
        refused = rt.tracker.spawn(swarm_cmd("watch", "--foxglove", busy), "watch-busy")
        assert refused.wait(DEADLINE) == ExitCode.USAGE
    finally:
        held.close()
    assert refused.text().strip().splitlines() == [
        f"--foxglove: cannot serve on 127.0.0.1:{busy}: Address already in use"
    ], refused.text()
    port, other = free_port(), free_port()
    watcher = rt.tracker.spawn(swarm_cmd("watch", "--foxglove", port), "watch")
    stays = rt.tracker.spawn(swarm_cmd("watch", f"--foxglove={other}"), "watch-to-the-end")
    ws = connect(port, 30, lambda: watcher.check_running("the live view"))
    try:
        channels = advertised(ws)
        assert set(channels) == set(LIVE_TOPICS), channels
        assert {t: c["encoding"] for t, c in channels.items()} == {
            "/swarm/scene": "protobuf",
            "/swarm/trails": "protobuf",
            "/swarm/agents": "json",
            "/swarm/events": "json",
            "/swarm/run": "json",
        }
        assert (
            channels["/swarm/scene"]["schemaName"] == channels["/swarm/trails"]["schemaName"] == "foxglove.SceneUpdate"
        )
        subs = {1: "/swarm/agents", 2: "/swarm/scene", 3: "/swarm/events"}
        ws.send_json(
            {"op": "subscribe", "subscriptions": [{"id": k, "channelId": channels[t]["id"]} for k, t in subs.items()]}
        )
        ids = {a.id for a in load_scenario(CASE2).agents}
        seen: set[int] = set()
        states: set[int] = set()  # agents whose follow state came (from their statuses)
        got_scene = False
        stream = messages(ws, subs)
        end = time.monotonic() + DEADLINE
        while not (seen == ids and got_scene and states == ids):
            assert time.monotonic() < end, f"poses seen of {sorted(seen)}, states of {sorted(states)}; {got_scene}"
            topic, doc = next(stream)
            if topic == "/swarm/agents":
                seen |= {
                    r["id"]
                    for r in doc["agents"]
                    if r["alive"] and isinstance(r["x"], float) and isinstance(r["radial_error"], float)
                }
                states |= {r["id"] for r in doc["agents"] if r.get("follow") in ("none", "acquire", "keep")}
            got_scene = got_scene or (topic == "/swarm/scene" and len(doc) > 0)
        victim = 3
        kill = rt.tracker.spawn(swarm_cmd("kill", victim, "--timeout", DEADLINE), "kill")
        assert kill.wait(DEADLINE) == ExitCode.OK, kill.text()
        end = time.monotonic() + DEADLINE
        dropped = dead = False
        while not (dropped and dead):
            assert time.monotonic() < end, f"after `swarm kill {victim}`: drop event {dropped}, shown dead {dead}"
            topic, doc = next(stream)
            if topic == "/swarm/events":
                dropped = dropped or (doc["kind"] == "drop" and doc["agent"] == victim)
            elif topic == "/swarm/agents":
                dead = any(r["id"] == victim and not r["alive"] for r in doc["agents"])
    finally:
        ws.close()
        os.kill(watcher.pid, signal.SIGINT)
    assert watcher.wait(DEADLINE) == ExitCode.INTERRUPTED, watcher.text()
    assert watcher.text().strip().splitlines()[-1] == "stopped (Ctrl-C); the live view is closed", watcher.text()
    assert up.launcher.poll() is None  # the run goes on without its watcher
    os.kill(up.launcher.pid, signal.SIGINT)
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    assert stays.wait(DEADLINE) == ExitCode.OK, stays.text()  # the other watcher saw the run end
    lines = stays.text().strip().splitlines()
    assert lines[0].startswith(f"run {up.banner()[0]}: live view: ws://127.0.0.1:{other}"), lines
    assert len(lines) == 2 and re.fullmatch(
        rf"run {up.banner()[0]} ended at tick \d+; the live view is closed", lines[1]
    ), lines
    rt.tracker.assert_none_left(timeout=DEADLINE)
