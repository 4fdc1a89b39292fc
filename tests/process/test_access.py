"""Only the run's own processes can act on it (docs/guides/security.md#access): every attack that worked on the
open hub, re-run against a real `swarm up` (realtime case2, at 20 Hz: its dt 0.05 s instead of 0.01 s,
the run's seven processes at a fifth of the CPU while the attacks wait) with real zenoh sessions.

The attacker is either a stranger (no credentials, or wrong ones) or an insider: a session
holding agent 5's identity, i.e. a compromised agent process, which is the strongest
attacker short of the operator. Each test asserts what the run shows afterwards (the
world's counters, the agents' processes, the launcher's output), not that a call failed.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import time

import psutil
import pytest
import zenoh
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, Runtime, UpRun, open_session, run_credentials, swarm_cmd, wait_for

from swarm.contracts import credentials, wire
from swarm.contracts.identities import SUPERVISOR, agent_user
from swarm.contracts.transport import open_client, query_statuses
from swarm.contracts.vocabulary import ExitCode, Phase

pytestmark = pytest.mark.slow

INSIDER = 5  # the agent whose identity the insider holds
REFUSE_MS = 1500


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One realtime case2 run for every attack of this module, started under umask 000 (the
    runtime dir and files must be private anyway); stopped and checked for leftovers."""
    d = tmp_path_factory.mktemp("access")
    with Runtime(d) as rt:
        # a runtime dir the run itself creates, under umask 000, in a directory others may
        # pass through (so that only the run's own modes keep another user out)
        os.chmod(rt.dir, 0o711)
        rt.env["SWARM_RUNTIME_DIR"] = os.path.join(rt.dir, "rt")
        scenario = d / "case2.toml"  # case2 at 20 Hz (no attack depends on the tick rate)
        text = (SCENARIOS / "case2.toml").read_text()
        assert "\ndt = 0.01\n" in text
        scenario.write_text(text.replace("\ndt = 0.01\n", "\ndt = 0.05\n", 1))
        args = swarm_cmd("up", scenario, "--out", d / "run", "--no-plots", "--clock", "realtime", "--duration", "600")
        up = UpRun(
            rt.tracker.spawn(["/bin/sh", "-c", 'umask 000; exec "$@"', "sh", *map(str, args)], "up"),
            d / "run",
            rt.tracker,
        )
        run_id, endpoint = up.banner()
        up.wait_started(DEADLINE)
        pids = rt.tracker.wait_agent_pids(up.launcher, 6)
        creds = run_credentials(endpoint, run_id)
        operator = open_session(endpoint, creds=creds)
        insider = open_session(endpoint, creds=creds, user=agent_user(INSIDER))
        try:
            yield {
                "up": up,
                "rt": rt,
                "run": run_id,
                "endpoint": endpoint,
                "pids": pids,
                "creds": creds,
                "operator": operator,
                "insider": insider,
            }
        finally:
            insider.close()
            operator.close()
            os.kill(up.launcher.pid, signal.SIGINT)
            assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
            rt.tracker.assert_none_left(timeout=DEADLINE)


def info(r) -> dict:
    return r["up"].info()


def ticks_on(r, seconds: float = 0.5) -> None:
    """The world keeps ticking (not paused, not stalled)."""
    t0 = info(r)["tick"]
    wait_for(lambda: info(r)["tick"] > t0, DEADLINE + seconds, "the world to keep ticking")


def all_alive(r) -> bool:
    return all(psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE for p in r["pids"].values())


# -- strangers ---------------------------------------------------------------------------------
NOBODY = 65534
PROBE = """
import json, os, socket, sys
rt, run = sys.argv[1], sys.argv[2]
out = {}
for what, act in [("list", lambda: os.listdir(rt)),
                  ("read", lambda: open(os.path.join(rt, run + ".cred")).read()),
                  ("connect", lambda: socket.socket(socket.AF_UNIX).connect(os.path.join(rt, run + ".sock")))]:
    try:
        act()
        out[what] = "ok"
    except OSError as e:
        out[what] = type(e).__name__
print(json.dumps(out))
"""


def test_runtime_dir_and_files_are_private_under_umask_000(run):
    rt = run["rt"].env["SWARM_RUNTIME_DIR"]
    assert stat.S_IMODE(os.stat(rt).st_mode) == 0o700  # made by `swarm up` under umask 000
    cred = os.path.join(rt, f"{run['run']}.cred")
    assert stat.S_IMODE(os.stat(cred).st_mode) == 0o600
    assert not [p for p in os.listdir(rt) if p.endswith(".users")]  # the hub's dictionary lived for its open only


@pytest.mark.skipif(os.getuid() != 0 or not os.path.exists("/usr/bin/python3"), reason="needs root and a system python")
def test_another_local_user_reaches_nothing(run):
    """Another user of the machine (it once paused a run through a world-writable socket)."""
    r = subprocess.run(
        ["/usr/bin/python3", "-c", PROBE, run["rt"].env["SWARM_RUNTIME_DIR"], run["run"]],
        user=NOBODY,
        capture_output=True,
        text=True,
        timeout=DEADLINE,
    )
    assert r.returncode == ExitCode.OK, r.stderr
    assert json.loads(r.stdout) == {"list": "PermissionError", "read": "PermissionError", "connect": "PermissionError"}


def test_no_credentials_refused_at_connect(run):
    with pytest.raises(zenoh.ZError):
        open_client(run["endpoint"], timeout_ms=REFUSE_MS).close()


@pytest.mark.parametrize("user,password", [("operator", "0" * 32), ("agent-3", "wrong"), ("root", "x")])
def test_wrong_credentials_refused_at_connect(run, user, password):
    forged = credentials.Credentials(run["run"], run["endpoint"], user=user, password=password)
    with pytest.raises(zenoh.ZError):
        open_client(run["endpoint"], timeout_ms=REFUSE_MS, creds=forged, user=user).close()


def test_credentials_of_another_run_refused(run):
    other = credentials.new_credentials(run["run"], run["endpoint"])  # same run id, another secret
    with pytest.raises(zenoh.ZError):
        open_client(run["endpoint"], timeout_ms=REFUSE_MS, creds=other).close()


# -- an insider: agent 5's identity ----------------------------------------------------------
def test_insider_reads_nothing_but_its_own(run):
    """The claim keys travel in every command: no one but the world (and the operator, the
    run's owner) may read them."""
    got = []
    sub = run["insider"].declare_subscriber(f"{wire.run_prefix(run['run'])}/**", lambda s: got.append(str(s.key_expr)))
    try:  # 20 ticks of the run (1 s at 20 Hz; longer on a loaded machine): a truth, 6 frames and 6 commands each
        t0 = info(run)["tick"]
        wait_for(lambda: info(run)["tick"] >= t0 + 20, DEADLINE, "20 ticks with the insider listening")
    finally:
        sub.undeclare()
    assert got == [], f"the insider read {len(got)} samples, e.g. {sorted(set(got))[:5]}"
    own = []
    sub = run["insider"].declare_subscriber(wire.agent_key(run["run"], INSIDER, "sense"), lambda s: own.append(1))
    try:
        wait_for(lambda: own, DEADLINE, "the insider's own frames (allowed)")
    finally:
        sub.undeclare()


def test_insider_cannot_steer_another_agent(run):
    """Forged commands on leader 1's key never reach the world: no rogue count, no garbage.
    (Ticks already reached: on an open hub the world would count each as rogue.)"""
    before = info(run)
    for k in range(200):
        cmd = wire.Command(
            agent=1, tick=max(before["tick"] - k, 0), u=-1.0, out=None, phase=Phase.ORBIT, hops=0, key=12345
        )
        run["insider"].put(wire.agent_key(run["run"], 1, "cmd"), wire.encode_cmd(cmd))
        time.sleep(0.002)
    time.sleep(0.5)
    after = info(run)
    assert after["agents"]["1"]["rogue_commands"] == before["agents"]["1"]["rogue_commands"] == 0
    assert after["garbage"] == before["garbage"]


def test_insider_cannot_pause_or_resume(run):
    for cmd in ("pause", "resume"):
        replies = list(
            run["insider"].get(wire.world_admin_key(run["run"]), payload=wire.encode_admin(cmd, by="evil"), timeout=1.0)
        )
        assert [r for r in replies if r.ok is not None] == []
    assert info(run)["paused"] is False
    ticks_on(run)


def test_insider_cannot_send_control_notices(run):
    """A forged fault notice (kill agent 2) and a forged `end`: nobody acts on them."""
    key = wire.world_control_key(run["run"])
    run["insider"].put(key, wire.encode_fault_notice(0, 1, {"kind": "kill", "agent": 2, "at": 0.0}))
    run["insider"].put(key, wire.encode_end(1))
    time.sleep(1.5)
    assert all_alive(run), "an agent exited after forged control notices"
    assert "fault" not in run["up"].launcher.text().lower()
    ticks_on(run)


def test_insider_cannot_signal_another_agent(run):
    run["insider"].put(wire.agent_key(run["run"], 2, "ctl"), wire.encode_ctl("KILL"))
    time.sleep(1.0)
    assert all_alive(run)
    assert info(run)["agents"]["2"]["alive"]


def test_insider_cannot_answer_for_another_agent(run):
    """A rogue status queryable for agent 1 (what `swarm kill 1` asks for the pid): the
    operator hears agent 1 itself only."""
    q = run["insider"].declare_queryable(
        wire.agent_key(run["run"], 1, "status"),
        lambda query: query.reply(
            wire.agent_key(run["run"], 1, "status"), wire.encode_status({"id": 1, "pid": 4242, "host": "evil"})
        ),
    )
    try:
        time.sleep(0.3)
        replies = [r for r in run["operator"].get(wire.agent_key(run["run"], 1, "status"), timeout=DEADLINE) if r.ok]
        pids = {json.loads(r.ok.payload.to_bytes())["pid"] for r in replies}
        assert pids == {run["pids"][1]}
        assert query_statuses(run["operator"], run["run"])[1]["pid"] == run["pids"][1]
    finally:
        q.undeclare()


def test_insider_cannot_answer_join_claims(run):
    """A rogue join reply (it once made an agent import a module of the rogue's choosing)."""
    q = run["insider"].declare_queryable(
        wire.agent_key(run["run"], "*", "join"),
        lambda query: query.reply(str(query.key_expr), wire.encode_join_reply(False, error="evil")),
    )
    try:
        time.sleep(0.3)
        # what an agent 2 claiming its id would hear (the world refuses: 2 is live)
        a2 = open_client(run["endpoint"], timeout_ms=5000, creds=run["creds"], user=agent_user(2))
        try:
            replies = [
                wire.decode_join_reply(r.ok.payload.to_bytes())
                for r in a2.get(
                    wire.agent_key(run["run"], 2, "join"), payload=wire.encode_join_request(2, 1, "h"), timeout=DEADLINE
                )
                if r.ok
            ]
        finally:
            a2.close()
        assert len(replies) == 1 and "already live" in replies[0]["error"], replies
    finally:
        q.undeclare()


def test_insider_cannot_claim_another_id(run):
    replies = list(
        run["insider"].get(
            wire.agent_key(run["run"], 3, "join"), payload=wire.encode_join_request(3, 1, "evil"), timeout=1.0
        )
    )
    assert [r for r in replies if r.ok is not None] == []
    # and not on its own key either, for another id: the world refuses
    replies = [
        wire.decode_join_reply(r.ok.payload.to_bytes())
        for r in run["insider"].get(
            wire.agent_key(run["run"], INSIDER, "join"),
            payload=wire.encode_join_request(3, 1, "evil"),
            timeout=DEADLINE,
        )
        if r.ok
    ]
    assert len(replies) == 1 and not replies[0]["ok"] and "another agent's join key" in replies[0]["error"]
    assert info(run)["agents"]["3"]["pid"] == run["pids"][3]


def test_insider_token_on_another_agents_key_is_not_routed(run):
    """A token on another id's key (it once kept a dead agent "active"): 7 is the first id
    an added agent may take; nobody holds it."""
    tok = run["insider"].liveliness().declare_token(wire.agent_key(run["run"], 7, "alive"))
    try:
        time.sleep(0.5)
        n = [r for r in run["operator"].liveliness().get(wire.agent_key(run["run"], 7, "alive"), timeout=1.0) if r.ok]
        assert n == [], f"{len(n)} tokens on agent 7's key"
        assert "7" not in info(run)["agents"]
    finally:
        tok.undeclare()


def test_oversized_payload_on_own_command_key_is_dropped_by_the_hub(run):
    """8 MiB on a command key once stalled every agent for 5-10 s and grew the world past
    1.2 GB; the hub drops it before Python sees it."""
    world = psutil.Process(run["rt"].tracker.world_pid(run["up"].launcher))
    rss0 = world.memory_info().rss
    before = info(run)
    big = bytes(8 << 20)
    for _ in range(8):
        run["insider"].put(wire.agent_key(run["run"], INSIDER, "cmd"), big)
    time.sleep(1.0)
    after = info(run)
    assert after["garbage"] == before["garbage"], "an oversized command reached the world"
    grew = (world.memory_info().rss - rss0) / 2**20
    assert grew < 64, f"the world grew {grew:.0f} MiB"
    assert all(a["alive"] for a in after["agents"].values())
    ticks_on(run)


# -- the operator can -----------------------------------------------------------------------------
def test_operator_can_pause_and_resume(run):
    for cmd, paused in (("pause", True), ("resume", False)):
        replies = [
            wire.decode_admin_reply(r.ok.payload.to_bytes())
            for r in run["operator"].get(
                wire.world_admin_key(run["run"]), payload=wire.encode_admin(cmd, by="test"), timeout=DEADLINE
            )
            if r.ok
        ]
        assert replies and replies[0]["ok"] and replies[0]["paused"] is paused
    ticks_on(run)


def test_operator_cannot_forge_commands_or_notices(run):
    """The operator acts on the run through the world (admin) and the agents (ctl) only."""
    before = info(run)
    run["operator"].put(
        wire.agent_key(run["run"], 1, "cmd"),
        wire.encode_cmd(
            wire.Command(agent=1, tick=before["tick"] + 1, u=1.0, out=None, phase=Phase.ORBIT, hops=0, key=1)
        ),
    )
    run["operator"].put(wire.world_control_key(run["run"]), wire.encode_end(1))
    time.sleep(1.0)
    assert info(run)["agents"]["1"]["rogue_commands"] == 0
    assert all_alive(run)


def test_operator_cannot_write_the_record(run):
    """Agent exits and faults done come from the launcher's `supervisor` identity
    alone. The operator's forged reports (a crash of live agent 5, a fault done) are refused
    on world/admin, never routed to world/supervise, and the run's secret does not give
    the supervisor's password: no report reaches the world, every agent stays in."""
    r = run["run"]
    for payload in (
        wire.encode_agent_exit(5, run["pids"][5], 1, True, "forged", []),
        wire.encode_admin("fault_done", index=0),
    ):
        admin = [
            wire.decode_admin_reply(x.ok.payload.to_bytes())
            for x in run["operator"].get(wire.world_admin_key(r), payload=payload, timeout=DEADLINE)
            if x.ok
        ]
        assert admin and not admin[0]["ok"] and "unknown cmd" in admin[0]["error"], admin
        assert not [
            x for x in run["operator"].get(wire.world_supervise_key(r), payload=payload, timeout=2.0) if x.ok
        ], "the hub let the operator's query reach the supervise key"
    with pytest.raises(zenoh.ZError):
        open_client(run["endpoint"], timeout_ms=REFUSE_MS, creds=run["creds"], user=SUPERVISOR).close()
    after = info(run)
    assert "supervise" not in after["over_limit"], after["over_limit"]
    assert all(a["alive"] for a in after["agents"].values()) and all_alive(run)
    ticks_on(run)
