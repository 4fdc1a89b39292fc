"""swarm/runtime/procs.py: the deadline poll and the process-group supervisor, on `sh`/`sleep`
children started here (no zenoh, well under a second each)."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
from deadlines import DEADLINE

from swarm.runtime.procs import Group, Reaper, group_runs, stop_groups, wait_until


def pid_runs(pid: int) -> bool:
    """`pid` exists and is not a zombie (an orphan's zombie may stay if init does not reap it)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except FileNotFoundError:
        return False
    return stat[stat.rindex(b")") + 2 :].split()[0] != b"Z"


def reaped(p: subprocess.Popen) -> bool:
    """No zombie of `p` is left for this process to collect."""
    try:
        return os.waitid(os.P_PID, p.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None and p.returncode is not None
    except ChildProcessError:
        return p.returncode is not None


def ignoring_term(g: Group) -> subprocess.Popen:
    """A `sleep 30` in `g` that ignores SIGTERM, once it does (it says so before the exec)."""
    p = g.start(["sh", "-c", 'trap "" TERM; echo ready; exec sleep 30'], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline() == "ready\n"
    p.stdout.close()
    return p


@pytest.fixture
def groups():
    """Groups a test starts; whatever is left of them is killed at the end."""
    made: list[Group] = []

    def make(session: bool = False) -> Group:
        g = Group(session=session)
        made.append(g)
        return g

    yield make
    for g in made:
        g.kill(timeout=2)


# --- wait_until -----------------------------------------------------------------------------------
def test_wait_until_returns_the_value_once_the_condition_holds():
    calls = []

    def cond():
        calls.append(1)
        return "ready" if len(calls) >= 3 else None

    assert wait_until(cond, 5.0, interval=0.001) == "ready"
    assert len(calls) == 3  # it returned on the first look that held


def test_wait_until_returns_false_at_the_deadline_after_a_last_look():
    seen = []
    t0 = time.monotonic()
    assert wait_until(lambda: seen.append(time.monotonic() - t0) or 0, 0.1, interval=0.02) is False
    assert seen[-1] >= 0.1 and len(seen) >= 3


def test_wait_until_counts_a_condition_that_holds_at_the_deadline():
    t0 = time.monotonic()
    assert wait_until(lambda: time.monotonic() - t0 >= 0.03, 0.03, interval=0.05) is True


def test_wait_until_with_no_time_looks_once():
    calls = []
    assert wait_until(lambda: calls.append(1), 0) is False and calls == [1]
    assert wait_until(lambda: 7, 0) == 7


# --- Group ----------------------------------------------------------------------------------------
def test_first_child_leads_a_new_group_and_the_next_join_it(groups):
    g = groups()
    a = g.start(["sleep", "30"])
    b = g.start(["sleep", "30"])
    assert g.pgid == a.pid == os.getpgid(a.pid) == os.getpgid(b.pid) != os.getpgrp()
    assert os.getsid(a.pid) == os.getsid(0), "process_group=0 keeps the session"
    s = groups(session=True)
    c = s.start(["sleep", "30"])
    assert os.getsid(c.pid) == os.getpgid(c.pid) == c.pid, "session=True: a new session"
    assert g.running() == [a, b] and g.alive()


def test_signal_reaches_every_member_and_stops_once_the_leader_is_reaped(groups):
    g = groups()
    ps = [g.start(["sleep", "30"]) for _ in range(3)]
    assert g.signal(signal.SIGUSR1)
    assert wait_until(lambda: not g.running(), 2.0)
    assert [g.exit_code(p) for p in ps] == [-signal.SIGUSR1] * 3
    assert ps[0].returncode is None, "exit_code reads the leader's status without reaping it"
    g.reap()
    assert all(reaped(p) for p in ps)
    assert not g.signal(signal.SIGUSR1), "once every member is reaped, the group id is not ours any more"
    assert not g.alive()


def test_the_group_is_signalled_while_any_member_is_unreaped(groups):
    g = groups()
    leader = g.start(["true"])
    member = g.start(["sleep", "30"])
    leader.wait()  # reaped (as a caller of Popen may do): the sleep still holds the group id
    assert g.signal(signal.SIGTERM)
    assert member.wait(DEADLINE) == -signal.SIGTERM
    assert not g.signal(signal.SIGTERM) and not g.alive()


def test_stop_terms_then_waits_no_longer_than_needed(groups):
    g = groups()
    p = g.start(["sleep", "30"])
    g.stop(grace=600.0)  # waiting out the grace would run into the test's own timeout
    assert p.returncode == -signal.SIGTERM and reaped(p) and not g.alive()


@pytest.mark.slow
def test_stop_kills_a_group_that_ignores_sigterm_after_the_grace(groups):
    g = groups()
    # sh and its sleep both ignore SIGTERM (an ignored signal stays ignored across exec).
    leader = g.start(["sh", "-c", 'trap "" TERM; sleep 30 & echo $!; wait'], stdout=subprocess.PIPE, text=True)
    sleeper = int(leader.stdout.readline())
    other = ignoring_term(g)
    assert os.getpgid(sleeper) == g.pgid
    t0 = time.monotonic()
    g.stop(grace=0.2)
    assert time.monotonic() - t0 >= 0.2  # it gave the group its grace before SIGKILL
    assert leader.returncode == other.returncode == -signal.SIGKILL
    assert reaped(leader) and reaped(other)
    assert not pid_runs(sleeper) and not g.alive() and group_runs(g.pgid) is False
    leader.stdout.close()


def test_alive_sees_a_grandchild_the_leader_left_and_reap_kills_it(groups):
    g = groups()
    leader = g.start(["sh", "-c", "sleep 30 & echo $!"], stdout=subprocess.PIPE, text=True)
    sleeper = int(leader.stdout.readline())
    assert wait_until(lambda: g.exit_code(leader) is not None, 2.0)
    assert g.exit_code(leader) == 0 and g.running() == []
    assert g.alive(), "the sleep left behind is still in the group"
    g.stop(grace=0.3)
    assert reaped(leader) and not pid_runs(sleeper) and not g.alive()
    leader.stdout.close()


@pytest.mark.slow  # waits out a grace period
def test_stop_groups_shares_one_grace_period(groups, tmp_path):
    """One grace for all, not one each: every group gets its SIGTERM while all of them still
    run (one after another, the second would get it only once the first was killed). Each
    member ignores SIGTERM but, on it, writes how many of the three members still run."""
    pids, log = tmp_path / "pids", tmp_path / "log"
    script = (
        f"trap 'n=0; for p in $(cat {pids}); do kill -0 $p 2>/dev/null && n=$((n+1)); done; "
        f"echo $n >> {log}' TERM; echo ready; while :; do sleep 0.05; done"
    )
    gs = [groups() for _ in range(3)]
    ps = []
    for g in gs:
        p = g.start(["sh", "-c", script], stdout=subprocess.PIPE, text=True)
        assert p.stdout.readline() == "ready\n"
        p.stdout.close()
        ps.append(p)
    pids.write_text(" ".join(str(p.pid) for p in ps))
    stop_groups(gs, grace=2.0)
    assert [p.returncode for p in ps] == [-signal.SIGKILL] * 3 and not any(g.alive() for g in gs)
    assert log.read_text().split() == ["3", "3", "3"], "a group got its SIGTERM after another was killed"


def test_an_empty_group_is_not_alive_and_stops_at_once():
    g = Group()
    assert not g.alive() and not g.signal(signal.SIGTERM) and g.running() == []
    g.stop()
    g.kill()


def test_the_reaper_reaps_members_as_they_exit_but_not_the_leader(groups):
    """A member killed from outside is no zombie while its owner is busy elsewhere (the
    launcher in a zenoh query): the Reaper thread reaps it; the leader waits for `reap()`."""

    g = groups()
    leader = g.start(["sleep", "30"])
    member = g.start(["sleep", "30"])
    reaper = Reaper(g, interval=0.02)
    try:
        os.kill(member.pid, signal.SIGKILL)
        os.kill(leader.pid, signal.SIGKILL)
        t0 = time.monotonic()
        assert wait_until(lambda: not os.path.exists(f"/proc/{member.pid}"), 10.0, 0.005), "member left a zombie"
        took = time.monotonic() - t0
        assert member.returncode == -signal.SIGKILL and reaped(member)
        time.sleep(0.05)  # a few rounds of the reaper
        assert leader.returncode is None and os.path.exists(f"/proc/{leader.pid}"), "the leader was reaped"
        assert g.exit_code(leader) == -signal.SIGKILL
        assert g.reap_exited() == []  # nothing new
    finally:
        reaper.stop()
    print(f"\n[timing] member reaped {took * 1000:.0f} ms after its SIGKILL")
