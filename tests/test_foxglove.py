"""The Foxglove side of a run: the recording's topics, and `--foxglove`, the live view served
over Foxglove's WebSocket protocol (world/live_view.py), watched by a real WebSocket client
(a minimal one, standard library only, below)."""

from __future__ import annotations

import base64
import json
import os
import signal
import socket
import struct
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from swarm.cli import app
from swarm.contracts.scenario import load_scenario
from world.live_view import LIVE_TOPICS, LiveViewError, start_live_view

REPO = Path(__file__).resolve().parents[1]
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


def test_recording_lists_the_topics(tmp_path):
    from mcap.reader import make_reader

    from swarm.sim import run_sim

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
    assert all(isinstance(r["u"], float) for r in agents[-2]["agents"])


def test_port_in_use_is_one_line():
    held, port = busy_port()
    try:
        for cmd in (["up", str(CASE2), "--foxglove", "--foxglove-port", str(port)],
                    ["world", str(CASE2), "--out", "/nonexistent/never", "--foxglove", "--foxglove-port", str(port)]):
            res = CliRunner().invoke(app, cmd)
            assert res.exit_code == 2, res.output
            lines = res.output.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("--foxglove: cannot serve on 127.0.0.1:"), res.output
        res = CliRunner().invoke(app, ["world", str(CASE2), "--foxglove"])
        assert res.exit_code == 2 and "--foxglove needs --out" in res.output
    finally:
        held.close()


def test_world_bind_failure_is_one_line(tmp_path):
    from world.stream import StreamWriter

    held, port = busy_port()
    w = StreamWriter(tmp_path / "r.mcap", load_scenario(CASE2), 10)
    try:
        with pytest.raises(LiveViewError) as e:
            start_live_view(w, "r", "127.0.0.1", port)
        assert "\n" not in str(e.value) and f"127.0.0.1:{port}" in str(e.value)
    finally:
        held.close()
        w.close()


# --- a minimal WebSocket client (RFC 6455), enough for the Foxglove protocol ------------------
# The protocol's subprotocol names: `foxglove.websocket.v1` as published, `foxglove.sdk.v1` as
# foxglove-sdk's server (0.30) names the same protocol (it accepts only that one); a client
# offers both, as the Foxglove app does, and the server picks one.
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")


class WsClient:
    def __init__(self, port: int, subprotocols=SUBPROTOCOLS, timeout: float = 10.0):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           f"Sec-WebSocket-Protocol: {', '.join(subprotocols)}\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            head += chunk
        head, self.buf = head.split(b"\r\n\r\n", 1)
        text = head.decode("latin-1")
        assert text.startswith("HTTP/1.1 101"), text
        picked = [ln.split(":", 1)[1].strip() for ln in text.split("\r\n")
                  if ln.lower().startswith("sec-websocket-protocol:")]
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
        head = bytes([0x80 | opcode]) + (bytes([0x80 | n]) if n < 126 else
                                         bytes([0x80 | 126]) + struct.pack(">H", n) if n < 65536 else
                                         bytes([0x80 | 127]) + struct.pack(">Q", n))
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
    up = start_up(rt.tracker, CASE2, tmp_path / "run", "--clock", "realtime", "--duration", "60",
                  "--foxglove", "--foxglove-port", port)
    try:
        ws = connect(port, 60, lambda: up.running("the live view"))
    except BaseException:
        os.kill(up.launcher.pid, signal.SIGINT)
        up.launcher.wait(60)
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
        ws.send_json({"op": "subscribe", "subscriptions": [{"id": k, "channelId": channels[t]["id"]}
                                                           for k, t in subs.items()]})
        ids = {a.id for a in load_scenario(CASE2).agents}
        seen: set[int] = set()
        got_scene = False
        end = time.monotonic() + 60
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
    assert up.launcher.wait(60) == 130
    assert f"ws://127.0.0.1:{port}" in up.launcher.text()
    assert (tmp_path / "run" / "summary.json").exists()
