"""Can strangers hold the hub's door? Idle connections against a live run, and the run's own
commands meanwhile.

    python benchmarks/bench_door.py [--listen tcp|tls|both] [--conns 300] [--attack 30] [--after 15]

For each listen kind: `swarm up scenarios/case2.toml --clock realtime --listen KIND/127.0.0.1:PORT`
in a private runtime dir; once `swarm runs` shows its 6 agents, an attacker (a thread of this
process) holds --conns plain TCP connections to the hub's port that connect and never send a
byte (one that the hub closes is opened again at once, so the count stays up) for --attack s,
then closes them all; the run is watched --after s more. Throughout, in a loop: `swarm agents
--run RUN` and `swarm spawn --run RUN --id K --x .. --speed ..` (K = 7, 8, ... 30: added ids, then
7 again, a dropped id rejoining; each is killed again, untimed, with `swarm kill`, so the load
stays that of case2), and `swarm agents --run RUN --connect KIND/127.0.0.1:PORT` ("agents-net":
through the network port, not the run's local door: docs/guides/security.md#door). Each call is a
fresh process, timed from start to exit (Python's start-up included). Printed per phase
(before / attack / after): calls, successes, within 2 s, median and max seconds, and the
first failure's message. Only processes started here are signalled (by process group).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import selectors
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

from swarm.contracts.vocabulary import ExitCode

REPO = Path(__file__).resolve().parents[1]
OK_S = 2.0


def swarm(*args) -> list[str]:
    return [sys.executable, "-m", "swarm", *map(str, args)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Attacker(threading.Thread):
    """Holds `n` idle TCP connections to `addr`, reopening any the other side closes."""

    def __init__(self, addr: tuple[str, int], n: int):
        super().__init__(daemon=True)
        self.addr, self.n = addr, n
        self.stop = threading.Event()
        self.sel = selectors.DefaultSelector()
        self.opened = self.closed_by_hub = self.failed = 0
        self.max_open = 0

    def _open(self) -> None:
        s = socket.socket()
        s.settimeout(1.0)
        try:
            s.connect(self.addr)
        except OSError:
            self.failed += 1
            s.close()
            return
        s.setblocking(False)
        self.sel.register(s, selectors.EVENT_READ)
        self.opened += 1

    def run(self) -> None:
        while not self.stop.is_set():
            while len(self.sel.get_map()) < self.n and not self.stop.is_set():
                self._open()
            self.max_open = max(self.max_open, len(self.sel.get_map()))
            for key, _ in self.sel.select(0.05):
                s = key.fileobj
                try:
                    gone = s.recv(4096) == b""
                except BlockingIOError:
                    gone = False
                except OSError:
                    gone = True
                if gone:
                    self.sel.unregister(s)
                    s.close()
                    self.closed_by_hub += 1
        for key in list(self.sel.get_map().values()):
            self.sel.unregister(key.fileobj)
            key.fileobj.close()


def hub_rss(root: int, port: int) -> str:
    """RSS of the process (under `root`) that listens on `port`."""

    for p in psutil.Process(root).children(recursive=True):
        try:
            if any(c.laddr and c.laddr.port == port and c.status == "LISTEN" for c in p.net_connections("tcp")):
                return f"{p.memory_info().rss / 2**20:.0f} MB (pid {p.pid})"
        except psutil.Error:
            continue
    return "unknown"


def timed(cmd: list[str], env: dict, timeout: float = 60.0) -> tuple[bool, float, str]:
    t0 = time.monotonic()
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=REPO)
        ok, msg = p.returncode == ExitCode.OK, (p.stderr.strip().splitlines() or [""])[-1]
    except subprocess.TimeoutExpired:
        ok, msg = False, f"timed out after {timeout} s"
    return ok, time.monotonic() - t0, msg


def wait_run(env: dict, up: subprocess.Popen, deadline: float = 90.0) -> str:
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        if up.poll() is not None:
            raise SystemExit(f"swarm up exited {up.returncode}")
        p = subprocess.run(swarm("runs", "--json"), env=env, capture_output=True, text=True, cwd=REPO)
        if p.returncode == ExitCode.OK:
            docs = json.loads(p.stdout)
            if len(docs) == 1 and docs[0]["agents_live"] == docs[0]["agents_total"] == 6:
                return docs[0]["run"]
        time.sleep(0.5)
    raise SystemExit("the run did not show 6 live agents in time")


def summary(rows: list[tuple[bool, float, str]]) -> str:
    if not rows:
        return "no calls"
    lat = [t for _, t, _ in rows]
    ok = sum(1 for o, _, _ in rows if o)
    fast = sum(1 for o, t, _ in rows if o and t <= OK_S)
    first_fail = next((m for o, _, m in rows if not o), "")
    return (
        f"{len(rows):3d} calls, {ok:3d} ok, {fast:3d} ok within {OK_S:g} s, "
        f"median {statistics.median(lat):5.2f} s, max {max(lat):5.2f} s"
        + (f"; first failure: {first_fail}" if first_fail else "")
    )


def bench(kind: str, conns: int, attack_s: float, after_s: float, before_s: float) -> None:
    rt = tempfile.mkdtemp(prefix="swdoor", dir="/tmp")
    out = Path(tempfile.mkdtemp(prefix="swdoor-out"))
    port = free_port()
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt}
    env.pop("SWARM_RUN", None), env.pop("SWARM_CONNECT", None), env.pop("SWARM_CREDENTIALS", None)
    log = open(out / "up.log", "wb")
    up = subprocess.Popen(
        swarm(
            "up",
            REPO / "scenarios/case2.toml",
            "--clock",
            "realtime",
            "--duration",
            "3600",
            "--listen",
            f"{kind}/127.0.0.1:{port}",
            "--out",
            out / "run",
            "--no-plots",
        ),
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
        cwd=REPO,
    )
    attacker = None
    try:
        run = wait_run(env, up)
        endpoint = f"{kind}/127.0.0.1:{port}"
        print(f"\n== {kind}: run {run} on {endpoint}, {conns} idle connections for {attack_s:g} s")
        phases: dict[str, dict[str, list]] = {
            p: {"agents": [], "agents-net": [], "spawn": []} for p in ("before", "attack", "after")
        }
        next_id, added = 7, set()
        t0 = time.monotonic()
        plan = [("before", before_s), ("attack", attack_s), ("after", after_s)]
        for phase, length in plan:
            if phase == "attack":
                attacker = Attacker(("127.0.0.1", port), conns)
                attacker.start()
                time.sleep(1.0)  # let it fill up
            end = time.monotonic() + length
            while time.monotonic() < end:
                for name, extra in (("agents", ()), ("agents-net", ("--connect", endpoint))):
                    r = timed(swarm("agents", "--run", run, *extra), env)
                    phases[phase][name].append(r)
                    print(
                        f"  t={time.monotonic() - t0:6.1f}s {phase:6s} {name:10s} {'ok  ' if r[0] else 'FAIL'} "
                        f"{r[1]:5.2f} s" + ("" if r[0] else f"  {r[2]}"),
                        flush=True,
                    )
                spec = () if next_id in added else ("--x", 5, "--y", 5, "--heading", 0, "--speed", 10)
                r = timed(swarm("spawn", "--run", run, "--id", next_id, *spec), env)
                added.add(next_id)
                phases[phase]["spawn"].append(r)
                print(
                    f"  t={time.monotonic() - t0:6.1f}s {phase:6s} spawn {next_id:2d} "
                    f"{'ok  ' if r[0] else 'FAIL'} {r[1]:5.2f} s" + ("" if r[0] else f"  {r[2]}"),
                    flush=True,
                )
                if r[0]:
                    timed(swarm("kill", "--run", run, next_id), env)
                next_id = 7 if next_id == 30 else next_id + 1  # past the cap: the dropped ids rejoin
            if phase == "attack":
                print(f"  hub RSS under attack: {hub_rss(up.pid, port)}")
                attacker.stop.set()
                attacker.join(10)
                print(
                    f"  attacker: {attacker.opened} connections opened (at most {attacker.max_open} at once), "
                    f"{attacker.closed_by_hub} closed by the hub, {attacker.failed} connects failed"
                )
        print(f"-- {kind}, {conns} idle connections:")
        for phase, _ in plan:
            for cmd in ("agents", "agents-net", "spawn"):
                print(f"  {phase:6s} {cmd:10s} {summary(phases[phase][cmd])}")
    finally:
        if attacker is not None:
            attacker.stop.set()
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGINT)
            try:
                up.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(up.pid, signal.SIGKILL)
                up.wait()
        log.close()
        shutil.rmtree(rt, ignore_errors=True)
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--listen", choices=("tcp", "tls", "both"), default="both")
    ap.add_argument("--conns", type=int, default=300)
    ap.add_argument("--attack", type=float, default=30.0, help="seconds the connections are held")
    ap.add_argument("--after", type=float, default=15.0, help="seconds watched after the attacker stops")
    ap.add_argument("--before", type=float, default=4.0, help="seconds watched before the attack")
    a = ap.parse_args()

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, max(soft, a.conns + 256)), hard))
    for kind in ("tcp", "tls") if a.listen == "both" else (a.listen,):
        bench(kind, a.conns, a.attack, a.after, a.before)


if __name__ == "__main__":
    main()
