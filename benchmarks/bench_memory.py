"""World memory as a run grows and as agents are added (docs/benchmarks.md#recording): it
should stay flat, less than 100 KB per added agent.

Starts `swarm up scenarios/case2.toml` on the realtime clock, measures the world's RSS once
it ticks, again after it has run a while (growth with time), then adds N agents at run
time through join requests with a spec (what `swarm spawn` sends; no agent process behind
them, so they join the recording and the world's tables but never fly) and measures again.

    python benchmarks/bench_memory.py            # 400 added agents
    python benchmarks/bench_memory.py --add 100 --run-for 10

Prints the figures; asserts nothing (targets are read by people, not by CI).
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import tempfile
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from up_banner import wait_banner  # noqa: E402

from swarm.contracts import credentials, wire  # noqa: E402
from swarm.contracts.transport import open_client  # noqa: E402
from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.runtime.procs import Group, wait_until  # noqa: E402


def rss_mb(pid: int) -> float:
    return psutil.Process(pid).memory_info().rss / 2**20


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--add", type=int, default=400, help="agents to add at run time")
    ap.add_argument("--run-for", type=float, default=20.0, help="wall s between the two growth samples")
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="swbm-"))
    env = {**os.environ, "SWARM_RUNTIME_DIR": str(work / "rt")}
    out = work / "run"
    # case2, with room for the agents this benchmark adds (the hub's rules name each of them)
    scenario = work / "case2-add.toml"
    scenario.write_text(
        (ROOT / "scenarios" / "case2.toml").read_text().replace("[run]\n", f"[run]\nmax_added_agents = {a.add}\n", 1)
    )
    group = Group(session=True)
    group.start(
        [
            sys.executable,
            "-m",
            "swarm",
            "up",
            str(scenario),
            "--out",
            str(out),
            "--clock",
            "realtime",
            "--duration",
            "3000",
            "--no-plots",
        ],
        env=env,
        stdout=open(work / "up.log", "wb"),
        stderr=open(work / "up.err", "wb"),
    )
    try:
        got = wait_banner(work / "up.log", 30)
        if not got:
            print("swarm up printed no banner; see", work / "up.log")
            return ExitCode.FAILED
        run, endpoint = got
        cred_file = work / "rt" / f"{run}{credentials.SUFFIX}"  # written by the world as it starts
        if not wait_until(cred_file.exists, 30, 0.1):
            print("the world wrote no credentials; see", work / "up.log")
            return ExitCode.FAILED
        creds = credentials.read(cred_file)
        ses = open_client(endpoint, timeout_ms=5000, creds=creds)

        def info():
            for r in ses.get(wire.world_info_key(run), timeout=2.0):
                if r.ok:
                    return wire.decode_info(r.ok.payload.to_bytes())
            return None

        first = wait_until(lambda: (i := info()) and i.get("started") and i, 60, 0.2)
        if not first:
            print("the run did not start")
            return ExitCode.FAILED
        pid = first["pid"]
        time.sleep(2.0)
        m0, t0 = rss_mb(pid), info()["time"]
        time.sleep(a.run_for)
        m1, t1 = rss_mb(pid), info()["time"]
        print(
            f"world RSS {m0:.1f} MB at t = {t0:.1f} s, {m1:.1f} MB at t = {t1:.1f} s: "
            f"{(m1 - m0) * 1024 / max(t1 - t0, 1e-9):.1f} KB per simulated s"
        )
        spec = {"role": "follower", "x": 50.0, "y": 50.0, "heading": 0.0, "speed": 10.0}
        host = socket.gethostname()
        ok = 0
        first_added = first["added_ids"][0]  # the ids the run reserves for added agents
        for aid in range(first_added, first_added + a.add):
            payload = wire.encode_join_request(aid, os.getpid(), host, spec)
            agent_ses = open_client(endpoint, timeout_ms=5000, creds=creds, user=credentials.agent_user(aid))
            try:
                for r in agent_ses.get(wire.agent_key(run, aid, "join"), payload=payload, timeout=5.0):
                    if r.ok and wire.decode_join_reply(r.ok.payload.to_bytes()).get("ok"):
                        ok += 1
            finally:
                agent_ses.close()
        time.sleep(2.0)
        m2, t2 = rss_mb(pid), info()["time"]
        time.sleep(a.run_for)
        m3, t3 = rss_mb(pid), info()["time"]
        print(
            f"added {ok}/{a.add} agents: world RSS {m1:.1f} -> {m2:.1f} MB "
            f"({(m2 - m1) * 1024 / max(ok, 1):.1f} KB per added agent); "
            f"{m3:.1f} MB at t = {t3:.1f} s ({(m3 - m2) * 1024 / max(t3 - t2, 1e-9):.1f} KB per simulated s "
            f"with {ok + 6} agents recorded)"
        )
        rec = out / "recording.mcap"
        print(f"recording.mcap: {rec.stat().st_size / 2**20:.1f} MB on disk")
        ses.close()
        return ExitCode.OK
    finally:
        group.signal(signal.SIGINT)
        group.stop(grace=20.0)


if __name__ == "__main__":
    raise SystemExit(main())
