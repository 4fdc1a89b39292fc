"""Three machines on one LAN, for real: Linux network namespaces on this machine
(docs/guides/several-machines.md#hosts).

`w` runs the world (`swarm world --listen tls/10.213.0.1:PORT`), `a` and `b` each run
`swarm host` for half of the agents, with the file `swarm credentials --host` wrote on
`w` and a runtime dir of their own (nothing of the run's is found locally). The
namespaces are joined by a bridge in `w` (the LAN's switch) and one veth pair per host,
so the only way from a host to the world is its veth link: each host's router connects
over it (TLS, as across machines), its agents connect to that router on a Unix socket.

- lockstep over the veth links equals `swarm sim` to the bit, every agent in the process
  its host started;
- an agent SIGKILLed on host b is dropped by the world (a `drop` event), which keeps
  ticking; the host reports the exit; nothing is left behind;
- Ctrl-C on a host stops its agents (the world drops them); a world killed makes the
  other host close its router, its agents exit 4 at once and the host exits 1.

The world's machine is watched by one observer process in `w` (the operator's view, as
`swarm agents --json` gives it, read every 0.1 s over one session: `swarm.connect`), not by
a `swarm agents` process per look.

Needs root (`ip netns add`); skips, saying why, where namespaces cannot be made. Every
namespace, and with it every link and address, is the test's own and is deleted at the
end, even on failure. Only processes the test started are ever signalled.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from deadlines import DEADLINE
from runtime_helpers import (
    SCENARIOS,
    events_of,
    load_trajectory,
    make_env,
    run_sim,
    short_runtime_dir,
    swarm_cmd,
    wait_for,
)

from swarm.contracts.vocabulary import EventKind, ExitCode

pytestmark = pytest.mark.slow

SUBNET = "10.213.0"  # a private /24 that exists only inside the test's namespaces
HOSTS = {"a": (1, 2, 3), "b": (4, 5, 6)}  # case2's agents: leader 1 on a, leader 6 on b


class LanError(Exception):
    pass


class Lan:
    """Network namespaces `w` and one per host (`a`, `b`; names unique to this process) on
    one /24 (`w` is .1, the hosts .2, .3, ...): a bridge in `w` with the world's address,
    a veth pair from it to each host. Made in the namespaces directly (`ip link add ...
    netns NS`): nothing touches the machine's own network. `down()` deletes the
    namespaces, and their links with them. Also used by benchmarks/bench_netns.py."""

    def __init__(self, hosts=("a", "b")):
        tag = f"swt-{os.getpid()}-{secrets.token_hex(2)}"
        self.hosts = tuple(hosts)
        self.ns = {k: f"{tag}-{k}" for k in ("w", *self.hosts)}
        self.address = {k: f"{SUBNET}.{i + 1}" for i, k in enumerate(("w", *self.hosts))}
        self.made: list[str] = []

    @staticmethod
    def _ip(*args: str) -> None:
        r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=DEADLINE)
        if r.returncode != ExitCode.OK:
            raise LanError(f"ip {' '.join(args)}: {r.stderr.strip() or f'exit code {r.returncode}'}")

    def up(self) -> Lan:
        try:
            for ns in self.ns.values():
                self.made.append(ns)  # (a failed add may leave its name behind: deleted too)
                self._ip("netns", "add", ns)
                self._ip("-n", ns, "link", "set", "lo", "up")
            w = self.ns["w"]
            self._ip("-n", w, "link", "add", "br0", "type", "bridge")
            for h in self.hosts:
                self._ip(
                    "link", "add", f"w{h}", "netns", w, "type", "veth", "peer", "name", "eth0", "netns", self.ns[h]
                )
                self._ip("-n", w, "link", "set", f"w{h}", "master", "br0")
                self._ip("-n", w, "link", "set", f"w{h}", "up")
                self._ip("-n", self.ns[h], "addr", "add", f"{self.address[h]}/24", "dev", "eth0")
                self._ip("-n", self.ns[h], "link", "set", "eth0", "up")
            self._ip("-n", w, "addr", "add", f"{self.address['w']}/24", "dev", "br0")
            self._ip("-n", w, "link", "set", "br0", "up")
        except BaseException:
            self.down()
            raise
        return self

    def down(self) -> list[str]:
        """Delete every namespace made here; returns the errors (none expected)."""
        errors = []
        listed = subprocess.run(
            ["ip", "netns", "list"], capture_output=True, text=True, timeout=DEADLINE
        ).stdout.split()
        for ns in reversed(self.made):
            if ns not in listed:
                continue  # its add failed
            try:
                self._ip("netns", "del", ns)
            except LanError as e:
                errors.append(str(e))
        self.made.clear()
        return errors

    def cmd(self, where: str, args: list) -> list[str]:
        """`args` run inside namespace `where` (ip netns exec execs it: same pid)."""
        return ["ip", "netns", "exec", self.ns[where], *map(str, args)]


def why_no_lan() -> str | None:
    """Why network namespaces cannot be made here (None: they can be tried)."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "network namespaces need root (ip netns add): run as root to test several hosts"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) to make network namespaces"
    return None


def lan_or_skip() -> Lan:
    why = why_no_lan()
    if why:
        pytest.skip(why)
    try:
        return Lan().up()
    except (LanError, OSError, subprocess.TimeoutExpired) as e:
        pytest.skip(f"cannot make network namespaces here: {e}")


def test_without_root_the_reason_to_skip_says_so(monkeypatch):
    monkeypatch.setattr(os, "geteuid", lambda: 1000)
    assert "need root" in why_no_lan()


@pytest.fixture(scope="module")
def lan():
    net = lan_or_skip()
    try:
        yield net
    finally:
        errors = net.down()
        assert not errors, errors
        names = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
        assert not any(ns in names for ns in net.ns.values()), names


# The observer on the world's machine: `swarm agents --json`'s document every 0.1 s over one
# operator session (swarm.connect, what `swarm agents` is made of), null (and why) while the run
# does not answer; each on a line of its own starting "DOC " (whatever else it may print).
OBSERVER = """\
import json, sys, time
from swarm.api.live import connect
run = sys.argv[1]
while True:
    try:
        with connect(run=run) as live:
            while True:
                snap = live.snapshot()
                info = snap["info"]
                doc = {k: info.get(k) for k in ("run", "scenario", "clock", "paused", "tick", "ticks", "time")}
                print("DOC", json.dumps({**doc, "agents": snap["agents"]}), flush=True)
                time.sleep(0.1)
    except Exception as e:  # no run (yet), or it stopped answering: said, and asked again
        print("DOC null", repr(e), flush=True)
        time.sleep(0.1)
"""


class Machines:
    """One run's processes on the three namespaces, each with a runtime dir of its own."""

    def __init__(self, lan: Lan, rt, tmp_path: Path, port: int):
        self.lan, self.rt, self.tmp = lan, rt, tmp_path
        self.run = f"mh-{secrets.token_hex(3)}"
        self.endpoint = f"tls/{lan.address['w']}:{port}"
        self.dirs = {"w": rt.dir, **{h: short_runtime_dir() for h in lan.hosts}}
        self.env = {k: make_env(d) for k, d in self.dirs.items()}
        self.out = tmp_path / "world"
        self.hosts = {}

    def cleanup(self) -> None:
        for h in self.lan.hosts:
            shutil.rmtree(self.dirs[h], ignore_errors=True)

    def start_world(self, *extra):
        args = swarm_cmd(
            "world",
            SCENARIOS / "case2.toml",
            "--listen",
            self.endpoint,
            "--run",
            self.run,
            "--clock",
            "lockstep",
            "--out",
            self.out,
            "--no-plots",
            *extra,
        )
        self.world = self.rt.tracker.spawn(self.lan.cmd("w", args), "world", env=self.env["w"])
        cred = Path(self.dirs["w"]) / f"{self.run}.cred"
        wait_for(
            lambda: self.world.check_running("its credentials") or cred.exists(), DEADLINE, "the world's credentials"
        )
        return self.world

    def start_hosts(self):
        for h, ids in HOSTS.items():
            f = self.tmp / f"host-{h}.cred"
            p = self.rt.tracker.spawn(
                swarm_cmd("credentials", "--host", h, "--agents", ",".join(map(str, ids)), "--run", self.run, "-o", f),
                f"credentials-{h}",
                env=self.env["w"],
            )
            assert p.wait(DEADLINE) == ExitCode.OK, p.text()
            doc = json.loads(f.read_text())
            assert doc["user"] == "host" and "secret" not in doc and sorted(doc["agents"]) == sorted(map(str, ids))
            assert doc["endpoint"] == self.endpoint
            self.hosts[h] = self.rt.tracker.spawn(
                self.lan.cmd(h, swarm_cmd("host", "--credentials", f, "--logs", self.tmp / f"logs-{h}")),
                f"host-{h}",
                env=self.env[h],
            )
        return self.hosts

    def observe(self) -> None:
        """Start the observer on the world's machine (as its operator): one process that
        prints `swarm agents --json`'s document (its tick and rows) every 0.1 s, or null
        while the run does not answer, until `stop_observing`."""
        self.observer = self.rt.tracker.spawn(
            self.lan.cmd("w", [sys.executable, "-c", OBSERVER, self.run]), "observer", env=self.env["w"]
        )

    def agents_json(self) -> dict | None:
        """The observer's latest `swarm agents --json` document (None before its first or when
        the run did not answer)."""
        self.observer.check_running("the run to answer")
        text = self.observer.text()
        lines = text.splitlines() if text.endswith("\n") else text.splitlines()[:-1]  # (not a line being written)
        docs = [ln for ln in lines if ln.startswith("DOC ")]  # (not what else the process may say)
        return None if not docs or docs[-1].startswith("DOC null") else json.loads(docs[-1][4:])

    def stop_observing(self) -> None:
        os.kill(self.observer.pid, signal.SIGTERM)
        self.observer.wait(DEADLINE)

    def agent_pids(self) -> dict[str, dict[int, int]]:
        return {h: self.rt.tracker.wait_agent_pids(t, len(HOSTS[h]), timeout=DEADLINE) for h, t in self.hosts.items()}

    def why(self) -> str:
        return "\n".join(f"--- {t.name}\n{t.text()[-2000:]}" for t in [self.world, *self.hosts.values()])

    def host_dirs_empty(self) -> None:
        for h in self.lan.hosts:
            left = list(Path(self.dirs[h]).iterdir())
            assert left == [], f"host {h} left {left}"


@pytest.fixture
def machines(lan, rt, tmp_path):
    made = []

    def make(port: int) -> Machines:
        m = Machines(lan, rt, tmp_path, port)
        made.append(m)
        return m

    yield make
    for m in made:
        m.cleanup()


def test_lockstep_over_veth_links_equals_sim(machines):
    m = machines(7447)
    # 10 s of case2: every choice of an out-neighbour is made by tick 1, then 1000 ticks of frames
    # and commands cross the links
    m.start_world("--duration", "10")
    m.start_hosts()
    pids = m.agent_pids()
    sim, _ = run_sim(m.rt.tracker, SCENARIOS / "case2.toml", m.tmp / "sim", "--duration", "10")
    assert m.world.wait(120) == ExitCode.OK, m.why()
    for h, t in m.hosts.items():
        assert t.wait(DEADLINE) == ExitCode.OK, m.why()
        assert f"host {h}: agents {', '.join(map(str, HOSTS[h]))}: exit code 0" in t.text(), t.text()
    m.rt.tracker.assert_none_left(timeout=DEADLINE)
    traj = load_trajectory(m.out)
    assert len(traj["t"]) == len(sim["t"]) == 1001
    for key in ("t", "x", "y", "heading", "u", "out", "alive"):
        np.testing.assert_array_equal(traj[key], sim[key], err_msg=key)
    summary = json.loads((m.out / "summary.json").read_text())
    assert summary["completed"] is True and summary["garbage_messages"] == 0
    assert summary["reproducible"] is True, summary["not_reproducible"]
    for h, ids in HOSTS.items():  # each agent was the process its host started, and joined once
        for aid in ids:
            ag = summary["agents"][str(aid)]
            assert (ag["pid"], ag["joins"], ag["commands"]) == (pids[h][aid], 1, summary["ticks"]), (aid, ag)
    assert events_of(summary, EventKind.DROP) == []
    assert events_of(summary, EventKind.SWITCH), "no runtime choice in the run compared"
    m.host_dirs_empty()
    print(f"lockstep over the veth links: {summary['ticks_per_second']:.0f} ticks/s")


def test_a_kill_on_one_host_is_noticed_by_the_world(machines):
    m = machines(7448)
    m.start_world("--duration", "600")
    m.start_hosts()
    m.observe()
    pids = m.agent_pids()

    def all_live(doc):
        return doc is not None and doc["tick"] > 0 and all(a["alive"] and a["answered"] for a in doc["agents"])

    doc = wait_for(lambda: all_live(m.agents_json()), DEADLINE, "every agent live and answering through its host")
    victim = 5  # on host b
    os.kill(pids["b"][victim], signal.SIGKILL)

    def dropped():
        d = m.agents_json()
        return d if d is not None and not {a["id"]: a for a in d["agents"]}[victim]["alive"] else None

    doc = wait_for(dropped, DEADLINE, f"the world to drop agent {victim}")
    wait_for(lambda: (d := m.agents_json()) is not None and d["tick"] > doc["tick"], DEADLINE, "the world to tick on")
    wait_for(
        lambda: f"agent {victim} (pid {pids['b'][victim]}) exited (killed by SIGKILL)" in m.hosts["b"].text(),
        DEADLINE,
        "host b to report the kill",
    )

    m.stop_observing()
    os.kill(m.world.pid, signal.SIGINT)
    assert m.world.wait(DEADLINE) == ExitCode.INTERRUPTED, m.why()
    for t in m.hosts.values():
        code = t.wait(DEADLINE)
        assert code == ExitCode.OK, m.why()  # the world's end notice reached every agent still running
    m.rt.tracker.assert_none_left(timeout=DEADLINE)
    summary = json.loads((m.out / "summary.json").read_text())
    drops = events_of(summary, EventKind.DROP)
    assert [e["agent"] for e in drops] == [victim], drops
    assert summary["agents"][str(victim)]["alive"] is False
    m.host_dirs_empty()


def test_a_host_stopped_and_a_world_killed(machines):
    m = machines(7449)
    m.start_world("--duration", "600")
    m.start_hosts()
    m.observe()
    pids = m.agent_pids()
    wait_for(
        lambda: (d := m.agents_json()) is not None and d["tick"] > 0 and all(a["alive"] for a in d["agents"]),
        DEADLINE,
        "every agent live",
    )
    os.kill(m.hosts["a"].pid, signal.SIGINT)  # Ctrl-C on host a
    assert m.hosts["a"].wait(DEADLINE) == ExitCode.INTERRUPTED, m.why()
    assert all(not _runs(p) for p in pids["a"].values())
    wait_for(
        lambda: (d := m.agents_json()) is not None and [a["id"] for a in d["agents"] if a["alive"]] == list(HOSTS["b"]),
        DEADLINE,
        "the world to drop a's agents",
    )
    m.stop_observing()
    os.kill(m.world.pid, signal.SIGKILL)
    assert m.hosts["b"].wait(DEADLINE) == ExitCode.FAILED, m.why()  # its agents saw the world gone: exit 4, at once
    text = m.hosts["b"].text()
    assert "is gone" in text and "router closed" in text and "agents 4, 5, 6: exit code 4" in text, text
    m.world.wait(DEADLINE)
    m.rt.tracker.assert_none_left(timeout=DEADLINE)
    m.host_dirs_empty()


def _runs(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
