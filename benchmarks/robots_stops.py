"""Stops that do not depend on the world (issue 34, item 2; docs/guides/robots.md#stops), timed
at the robots' side: a simulated fleet (swarm/robots/fleet.py `Fleet`, in this process, on its
own router) records when each command reached each robot (monotonic s, as it arrived in the
robot's subscription), and every figure is from the fault to the zero twist's arrival, the
slowest robot of each run, median and max over the runs.

1. world SIGKILL: `swarm up --robots` of a 6-robot scenario against the fleet; once every robot
   moves, SIGKILL its world: until every robot got `swarm up`'s zero twist.
2. e-stop: `swarm estop` started as a process (a second terminal) with the world running,
   stalled (SIGSTOP) or killed (SIGKILL, 0.5 s before: `swarm up`'s own zero twists are
   over by then, so only the e-stop's count): from the `Popen` of `swarm estop` until every
   robot got a zero twist sent after it; also the e-stop's own figure (its line: from the
   start of its work to the zero twists sent) and the time until the run had ended. And
   `swarm estop --ready` (connected and waiting in its terminal): from Enter to the zeros.
3. guard (root only): the world in a network namespace of its own, linked to the fleet's
   router by a veth pair; `swarm robots guard` next to the router; the link cut with `ip link
   set ... down` while every robot moves: from the last command each robot got (and from the
   cut) to the guard's zero twist; then the link up again, the robots driven again, the next
   cut. Everything created is deleted at the end.

    .venv/bin/python benchmarks/robots_stops.py                 # 20 runs of each (~20 min)
    .venv/bin/python benchmarks/robots_stops.py --runs 3 --only kill,estop-running
    sudo .venv/bin/python benchmarks/robots_stops.py --only guard

Prints one table (ms): case, runs, median, max, and the bound the issue sets.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import psutil  # noqa: E402
import zenoh  # noqa: E402

from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.robots.config import load_robots  # noqa: E402
from swarm.robots.fleet import Fleet, FleetOptions, router_config  # noqa: E402
from swarm.ros2 import cdr  # noqa: E402

SWARM = [sys.executable, "-m", "swarm"]
N_ROBOTS = 6
DEADLINE = 120.0
NS, VETH, VETH_NS = "swarmstop", "vswst0", "vswst1"
HOST_IP, NS_IP = "10.231.77.1", "10.231.77.2"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def scenario_of_six(path: Path) -> Path:
    """scenarios/turtlebot.toml's leader with five followers on the realtime clock."""
    text = (ROOT / "scenarios" / "turtlebot.toml").read_text().replace('clock = "lockstep"', 'clock = "realtime"')
    for k in range(3, N_ROBOTS + 1):
        x = 1.2 + 0.4 * k
        text += (
            f'\n[[agents]]\nid = {k}\nrole = "follower"\nx = {x}\ny = {-0.3 * k}\nheading = 2.4\n'
            "speed = 0.15\nfollow = 1\nmax_turn_rate = 2.84\n"
        )
    path.write_text(text)
    return path


def robots_of(endpoint: str, path: Path) -> Path:
    lines = ["[ros2]", f'connect = "{endpoint}"']
    for k in range(1, N_ROBOTS + 1):
        lines += ["[[robots]]", f"agent = {k}", f'namespace = "/tb3_{k - 1}"', "quantize = 0.01"]
    path.write_text("\n".join(lines) + "\n")
    return path


class RecordingFleet(Fleet):
    """The fleet, each command's arrival recorded: (monotonic s, agent, linear, angular)."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.arrivals: list[tuple[float, int, float, float]] = []
        self.lock = threading.Lock()

    def _on_command(self, r):
        inner = super()._on_command(r)
        stamped = r.cmd_type == "TwistStamped"

        def on_sample(payload: bytes) -> None:
            now = time.monotonic()
            try:
                vx, wz = cdr.decode_twist_stamped(payload)[2:] if stamped else cdr.decode_twist(payload)
            except cdr.CdrError:
                return
            with self.lock:
                self.arrivals.append((now, r.spec.agent, vx, wz))
            inner(payload)

        return on_sample

    def since(self, t: float) -> list[tuple[float, int, float, float]]:
        with self.lock:
            return [a for a in self.arrivals if a[0] > t]

    def moving_since(self, t: float) -> bool:
        moved = {a for when, a, vx, wz in self.since(t) if (vx, wz) != (0.0, 0.0)}
        return len(moved) == N_ROBOTS

    def zero_after(self, t: float) -> dict[int, float]:
        """agent -> the first zero twist's arrival after `t`."""
        out: dict[int, float] = {}
        for when, a, vx, wz in self.since(t):
            if (vx, wz) == (0.0, 0.0) and a not in out:
                out[a] = when
        return out

    def last_command_before(self, t: float) -> dict[int, float]:
        out: dict[int, float] = {}
        with self.lock:
            for when, a, _vx, _wz in self.arrivals:
                if when <= t:
                    out[a] = when
        return out


def wait_until(cond, timeout: float, what: str, interval: float = 0.005):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = cond()
        if v:
            return v
        time.sleep(interval)
    raise SystemExit(f"timed out waiting for {what}")


def world_of(launcher: subprocess.Popen) -> int:
    def find():
        try:
            for c in psutil.Process(launcher.pid).children(recursive=True):
                cmd = c.cmdline()
                if "world" in cmd and "swarm" in cmd:
                    return c.pid
        except psutil.Error:
            pass
        return None

    return wait_until(find, DEADLINE, "the world's pid", 0.05)


class Bench:
    def __init__(self, work: Path, listen_ip: str = "127.0.0.1"):
        self.work = work
        self.env = {**os.environ, "SWARM_RUNTIME_DIR": str(work / "rt"), "PYTHONUNBUFFERED": "1"}
        (work / "rt").mkdir(mode=0o700, exist_ok=True)
        self.endpoint = f"tcp/{listen_ip}:{free_port() if listen_ip == '127.0.0.1' else 17447}"
        self.scenario = scenario_of_six(work / "six.toml")
        self.robots = robots_of(self.endpoint, work / "robots.toml")
        self.session = zenoh.open(router_config(self.endpoint))
        self.fleet = RecordingFleet(
            load_robots(self.robots),
            load_scenario(self.scenario),
            FleetOptions(cmd_timeout=3600.0),  # no watchdog on the robots: only our stops stop them
            out=lambda _l: None,
        )
        self.fleet.open(self.session)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.fleet.run, args=(self.stop,), daemon=True)
        self.thread.start()
        self.k = 0

    def up(self, prefix: list[str] | None = None) -> subprocess.Popen:
        self.k += 1
        out = self.work / f"run{self.k}"
        log = open(self.work / f"up{self.k}.log", "wb")
        cmd = (prefix or []) + SWARM + ["up", str(self.scenario), "--robots", str(self.robots)]
        cmd += ["--out", str(out), "--no-plots", "--duration", "600"]
        p = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        p.log = self.work / f"up{self.k}.log"  # type: ignore[attr-defined]
        t = time.monotonic()
        wait_until(lambda: p.poll() is not None or self.fleet.moving_since(t), DEADLINE, "the robots to move", 0.02)
        if p.poll() is not None:
            raise SystemExit(f"swarm up exited {p.returncode}: {p.log.read_text()[-2000:]}")  # type: ignore[attr-defined]
        time.sleep(0.3)
        return p

    def finish(self, p: subprocess.Popen) -> None:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)
        try:
            p.wait(DEADLINE)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()

    def slowest(self, t: float) -> float:
        zeros = wait_until(lambda: (z := self.fleet.zero_after(t)) and len(z) == N_ROBOTS and z, 30.0, "zero twists")
        return max(zeros.values()) - t

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.fleet.close()
        self.session.close()


def bench_kill(b: Bench, runs: int) -> list[float]:
    out = []
    for _ in range(runs):
        p = b.up()
        world = world_of(p)
        t = time.monotonic()
        os.kill(world, signal.SIGKILL)
        out.append(b.slowest(t))
        b.finish(p)
        print(f"  kill: {out[-1] * 1000:.1f} ms", flush=True)
    return out


def bench_estop(b: Bench, runs: int, state: str) -> tuple[list[float], list[float], list[float]]:
    delays, own, ended = [], [], []
    for _ in range(runs):
        p = b.up()
        world = world_of(p)
        if state == "stalled":
            os.kill(world, signal.SIGSTOP)
        elif state == "killed":
            os.kill(world, signal.SIGKILL)
            time.sleep(0.5)
        t = time.monotonic()
        e = subprocess.run(SWARM + ["estop"], env=b.env, capture_output=True, text=True, timeout=DEADLINE)
        done = time.monotonic()
        if e.returncode != 0:
            raise SystemExit(f"swarm estop exited {e.returncode}: {e.stdout}{e.stderr}")
        delays.append(b.slowest(t))
        line = next(ln for ln in e.stdout.splitlines() if "zero twist sent" in ln)
        own.append(float(line.rsplit("(", 1)[1].split(" ms")[0]) / 1000)
        p.wait(DEADLINE)  # the run has ended
        ended.append(max(done, time.monotonic()) - t)
        b.finish(p)
        print(f"  estop {state}: {delays[-1] * 1000:.1f} ms (its own {own[-1] * 1000:.0f} ms)", flush=True)
    return delays, own, ended


def bench_ready(b: Bench, runs: int) -> list[float]:
    """`swarm estop --ready` (connected, waiting), Enter with the world running."""
    delays = []
    for _ in range(runs):
        p = b.up()
        e = subprocess.Popen(
            SWARM + ["estop", "--ready"], env=b.env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert e.stdin is not None and e.stdout is not None
        line = e.stdout.readline()
        if "estop ready" not in line:
            raise SystemExit(f"swarm estop --ready: {line}")
        t = time.monotonic()
        e.stdin.write("\n")
        e.stdin.flush()
        delays.append(b.slowest(t))
        e.stdin.close()
        if e.wait(DEADLINE) != 0:
            raise SystemExit(f"swarm estop --ready exited {e.returncode}: {e.stdout.read()}")
        p.wait(DEADLINE)
        b.finish(p)
        print(f"  estop --ready: {delays[-1] * 1000:.1f} ms", flush=True)
    return delays


def sh(*args: str, check: bool = True) -> None:
    subprocess.run(list(args), check=check, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def netns_up() -> None:
    sh("ip", "netns", "add", NS)
    sh("ip", "link", "add", VETH, "type", "veth", "peer", "name", VETH_NS)
    sh("ip", "link", "set", VETH_NS, "netns", NS)
    sh("ip", "addr", "add", f"{HOST_IP}/24", "dev", VETH)
    sh("ip", "link", "set", VETH, "up")
    sh("ip", "netns", "exec", NS, "ip", "addr", "add", f"{NS_IP}/24", "dev", VETH_NS)
    sh("ip", "netns", "exec", NS, "ip", "link", "set", VETH_NS, "up")
    sh("ip", "netns", "exec", NS, "ip", "link", "set", "lo", "up")


def netns_down() -> None:
    sh("ip", "link", "del", VETH, check=False)
    sh("ip", "netns", "del", NS, check=False)


def bench_guard(work: Path, runs: int, cmd_timeout: float) -> tuple[list[float], list[float]]:
    netns_down()
    netns_up()
    b = guard = p = None
    from_last, from_cut = [], []
    try:
        (work / "guard").mkdir(exist_ok=True)
        b = Bench(work / "guard", HOST_IP)
        glog = open(work / "guard.log", "wb")
        guard = subprocess.Popen(
            SWARM + ["robots", "guard", "--robots", str(b.robots), "--cmd-timeout", str(cmd_timeout)],
            env=b.env,
            stdout=glog,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        wait_until(lambda: b"Ctrl-C stops it" in (work / "guard.log").read_bytes(), DEADLINE, "the guard")
        p = b.up(["ip", "netns", "exec", NS])
        for _ in range(runs):
            t = time.monotonic()
            wait_until(lambda t=t: b.fleet.moving_since(t), DEADLINE, "the robots to move", 0.02)
            time.sleep(0.5)
            cut = time.monotonic()
            sh("ip", "link", "set", VETH, "down")
            zeros = wait_until(
                lambda cut=cut: (z := b.fleet.zero_after(cut)) and len(z) == N_ROBOTS and z, 30.0, "the guard"
            )
            last = b.fleet.last_command_before(cut)
            from_last.append(max(zeros[a] - last[a] for a in zeros))
            from_cut.append(max(zeros.values()) - cut)
            print(
                f"  guard: {from_last[-1] * 1000:.1f} ms after the last command, "
                f"{from_cut[-1] * 1000:.1f} ms after the cut",
                flush=True,
            )
            sh("ip", "link", "set", VETH, "up")
    finally:
        if p is not None:
            b.finish(p)  # type: ignore[union-attr]
        if guard is not None:
            guard.send_signal(signal.SIGINT)
            guard.wait(DEADLINE)
        if b is not None:
            b.close()
        netns_down()
    return from_last, from_cut


def row(name: str, values: list[float], bound: str) -> str:
    ms = [v * 1000 for v in values]
    return f"| {name} | {len(ms)} | {statistics.median(ms):.1f} | {max(ms):.1f} | {bound} |"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--only", default="kill,estop-running,estop-stalled,estop-killed,estop-ready,guard")
    ap.add_argument("--cmd-timeout", type=float, default=0.5)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    only = set(a.only.split(","))
    work = Path(tempfile.mkdtemp(prefix="rs-", dir="/tmp"))
    rows, figures = [], {}
    b = Bench(work) if only & {"kill", "estop-running", "estop-stalled", "estop-killed", "estop-ready"} else None
    try:
        if "kill" in only and b is not None:
            figures["kill"] = v = bench_kill(b, a.runs)
            rows.append(row("world SIGKILL -> swarm up's zero twist", v, "0.5 s"))
        for state in ("running", "stalled", "killed"):
            if f"estop-{state}" in only and b is not None:
                d, own, ended = bench_estop(b, a.runs, state)
                figures[f"estop-{state}"] = {"delay": d, "own": own, "ended": ended}
                rows.append(row(f"swarm estop, world {state}: Popen -> zero twist", d, "0.2 s"))
                rows.append(row(f"swarm estop, world {state}: its own start -> sent", own, ""))
                rows.append(row(f"swarm estop, world {state}: Popen -> run ended", ended, ""))
        if "estop-ready" in only and b is not None:
            figures["estop-ready"] = v = bench_ready(b, a.runs)
            rows.append(row("swarm estop --ready, world running: Enter -> zero twist", v, "0.2 s"))
    finally:
        if b is not None:
            b.close()
    if "guard" in only:
        last, cut = bench_guard(work, a.runs, a.cmd_timeout)
        figures["guard"] = {"from_last": last, "from_cut": cut}
        rows.append(
            row(f"guard (cmd_timeout {a.cmd_timeout:g} s): last command -> zero", last, f"{a.cmd_timeout + 0.1:g} s")
        )
        rows.append(
            row(f"guard (cmd_timeout {a.cmd_timeout:g} s): link cut -> zero", cut, f"{a.cmd_timeout + 0.1:g} s")
        )
    print("\n| case | runs | median (ms) | max (ms) | bound |\n| --- | --- | --- | --- | --- |")
    print("\n".join(rows))
    if a.json is not None:
        a.json.write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
