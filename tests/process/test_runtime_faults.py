"""Faults in a distributed run: killed, restarted, duplicated, frozen agents and a
vanishing world. Real processes over real zenoh; see tests/support/runtime_helpers.py. While a
run goes, the tests wait on the world's info (its drop and join counters); the events
themselves are checked in summary.json once the run has ended.
"""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pytest
from deadlines import DEADLINE
from runtime_helpers import (
    SCENARIOS,
    Runtime,
    agent_cmd,
    agent_info,
    check_time_column,
    events_of,
    first_ticks,
    has_started,
    observe_world,
    replay_events,
    sim_results,
    start_ticking,
    start_up,
    swarm_cmd,
)

from swarm.contracts.vocabulary import AgentState, EventKind, ExitCode
from swarm.runtime.procs import wait_until

pytestmark = pytest.mark.slow


# --- 3 + 4: SIGKILL a follower and a leader mid-run, restart the follower ----------------------------
# A restarted agent process needs ~0.5-4 s to import, connect and claim its id on 2 busy cores
# while the lockstep world runs at full speed (~500 ticks/s), so the run is set far longer than
# the faults need (the slack for a loaded machine), and is ended with Ctrl-C once the rejoin is
# seen and the clock has gone on past it (a few hundred ticks; 6000 ticks when it ran its whole
# 60 s, ~9 s of wall time more).
FAULT_DURATION = 300.0  # s: never reached; the kills and the rejoin are done in the first few s of wall time
TICKS_AFTER_REJOIN = 200  # the clock goes on this far past the rejoin before the Ctrl-C


@pytest.fixture(scope="module")
def fault_run(tmp_path_factory):
    """case2-fixed (the pinned graph) through `swarm up`: SIGKILL follower 4 (5 pins it), then
    leader 1 (2 and 3 pin it), then start agent 4 again by hand; once the world has seen it
    rejoin and ticked TICKS_AFTER_REJOIN more, Ctrl-C ends the run."""
    base = tmp_path_factory.mktemp("faults")
    with Runtime(base) as r:
        tr = r.tracker
        up = start_up(
            tr, SCENARIOS / "case2-fixed.toml", base / "run", "--duration", FAULT_DURATION, "--clock", "lockstep"
        )
        run_id, endpoint = up.banner()
        up.wait_started(DEADLINE)
        pids = tr.wait_agent_pids(up.launcher, 6)
        # Mid-run: the world ticks, and nobody was dropped.
        info = up.wait_info(lambda i: i["tick"] > 0, DEADLINE, "the run to tick")
        assert not [a for a in info["agents"].values() if a["drops"]], info["agents"]
        res = {"up": up, "run_id": run_id, "endpoint": endpoint, "pids": dict(pids), "kill_time": {}}

        for victim in (4, 1):
            res["kill_time"][victim] = time.time()
            os.kill(pids[victim], signal.SIGKILL)
            up.wait_info(lambda i, v=victim: agent_info(i, v)["drops"], DEADLINE, f"the world to drop agent {victim}")
        assert up.launcher.poll() is None, "the run ended before the faults were done: make it longer"
        # The clock goes on after the drops before agent 4 comes back (lockstep: had the world
        # still been waiting on this tick, the drop and the rejoin would share it).
        k = up.info()["tick"]
        up.wait_info(lambda i: i["tick"] > k + 2, DEADLINE, "the clock to go on after the drops")

        t_again = time.monotonic()
        again = tr.spawn(agent_cmd(4, endpoint, run_id), "agent-4-again")
        res["again"] = again
        try:
            up.wait_info(
                lambda i: agent_info(i, 4)["joins"] == 2 and agent_info(i, 4)["alive"],
                DEADLINE,
                "the restarted agent 4 to rejoin",
            )
        except AssertionError as e:
            raise AssertionError(f"{e}\nthe restarted agent 4 said:\n{again.text()}") from None
        res["restart_to_rejoin_s"] = time.monotonic() - t_again
        print(f"\n[timing] restart of agent 4 -> rejoin seen live: {res['restart_to_rejoin_s']:.2f} s")
        k = up.info()["tick"]
        up.wait_info(lambda i: i["tick"] > k + TICKS_AFTER_REJOIN, DEADLINE, "the clock to go on after the rejoin")
        assert up.launcher.poll() is None, "the run ended before the Ctrl-C: make it longer"
        t_stop = time.monotonic()
        os.kill(up.launcher.pid, signal.SIGINT)
        res["rc"] = up.launcher.wait(DEADLINE)
        print(
            f"[timing] rejoin -> Ctrl-C: {t_stop - t_again - res['restart_to_rejoin_s']:.2f} s; "
            f"Ctrl-C -> launcher exit: {time.monotonic() - t_stop:.2f} s"
        )
        res["again_rc"] = again.wait(DEADLINE)
        tr.assert_none_left(timeout=DEADLINE)
        res["summary"] = up.summary()
        res["traj"] = up.trajectory()
        yield res


def _drop_event(summ: dict, agent: int) -> dict:
    drops = events_of(summ, EventKind.DROP, agent)
    assert len(drops) == 1, f"agent {agent}: drop events {drops}"
    return drops[0]


def _check_followers_switch(res: dict, victim: int, expected_followers: set[int]) -> None:
    summ, traj = res["summary"], res["traj"]
    ids = [int(i) for i in traj["ids"]]
    col = {a: k for k, a in enumerate(ids)}
    drop = _drop_event(summ, victim)
    k = drop["tick"]
    assert k >= 1, "the kill happened before the run was ticking"
    # Who had the victim as out-neighbour just before the drop took effect.
    followers = {a for a in ids if traj["out"][k - 1, col[a]] == victim}
    assert expected_followers <= followers, f"followers of {victim} before its drop: {followers}"
    for f in sorted(followers):
        sw = [e for e in events_of(summ, EventKind.SWITCH, f) if e["tick"] >= k]
        assert sw, f"agent {f} never switched away from dropped agent {victim}"
        first = sw[0]
        assert first["tick"] <= k + 1, (
            f"agent {f} switched at tick {first['tick']}, more than one tick after drop tick {k}"
        )
        assert first["from"] == victim and first["to"] is not None and first["to"] != victim, first
        # The recording shows the new neighbour from the switch until f's next switch.
        nxt = sw[1]["tick"] if len(sw) > 1 else len(traj["t"])
        seg = traj["out"][first["tick"] : nxt, col[f]]
        assert (seg == first["to"]).all(), f"agent {f}: out column {np.unique(seg)} after its switch"
        assert (traj["out"][k : first["tick"], col[f]] == victim).all()


@pytest.mark.parametrize("victim, followers", [(4, {5}), (1, {2, 3})], ids=["follower", "leader"])
def test_sigkill_detected_and_replaced(fault_run, victim, followers):
    res = fault_run
    drop = _drop_event(res["summary"], victim)
    latency = drop["wall_time"] - res["kill_time"][victim]
    print(f"\n[timing] SIGKILL agent {victim} -> drop event {1000 * latency:.1f} ms")
    assert latency >= 0 and "liveliness" in drop["reason"] and drop["now"] == AgentState.GONE, drop
    _check_followers_switch(res, victim, followers)


def test_run_goes_on_after_kills(fault_run):
    res = fault_run
    summ, traj = res["summary"], res["traj"]
    # Ended by the Ctrl-C once agent 4 was back: its results are written like a whole run's.
    assert res["rc"] == 130, res["up"].launcher.text()[-3000:]
    assert summ["completed"] is False and summ["stopped_by_signal"] == signal.SIGINT, summ
    ticks = summ["ticks"]
    rejoin = events_of(summ, EventKind.REJOIN, 4)
    assert rejoin and ticks > rejoin[0]["tick"] + TICKS_AFTER_REJOIN, (ticks, rejoin)
    check_time_column(traj, ticks, 0.01)
    # The events tell the story, with reasons, in order.
    kinds = [(e["kind"], e["agent"]) for e in summ["events"] if e["kind"] in (EventKind.DROP, EventKind.REJOIN)]
    assert kinds == [(EventKind.DROP, 4), (EventKind.DROP, 1), (EventKind.REJOIN, 4)], kinds
    # Kills from outside: `swarm sim` cannot do the same, and the summary says so.
    assert summ["reproducible"] is False
    churn = [r.split(" at tick")[0] for r in summ["not_reproducible"] if r.startswith("agent ")]
    assert churn == ["agent 4 dropped", "agent 1 dropped", "agent 4 joined"], summ["not_reproducible"]
    for e in summ["events"]:
        assert e.get("reason"), e
    assert summ["agents"]["1"]["drops"] == 1 and summ["agents"]["1"]["alive"] is False
    assert summ["agents"]["4"]["drops"] == 1 and summ["agents"]["4"]["joins"] == 2
    for aid in ("2", "3", "5", "6"):
        assert summ["agents"][aid]["drops"] == 0 and summ["agents"][aid]["joins"] == 1
    # The world's join events name the processes the launcher started (found with psutil).
    joins = {e["agent"]: e["pid"] for e in events_of(summ, EventKind.JOIN)}
    assert joins == res["pids"], (joins, res["pids"])
    # The out and alive columns are exactly what the events say, at every tick.
    rep_out, rep_alive = replay_events(summ["events"], traj["ids"], ticks + 1)
    np.testing.assert_array_equal(traj["out"], rep_out)
    np.testing.assert_array_equal(traj["alive"], rep_alive)
    # Poses are finite throughout (dropped agents are frozen, not NaN).
    assert np.isfinite(traj["x"]).all() and np.isfinite(traj["y"]).all()
    assert summ["garbage_messages"] == 0


def test_restarted_agent_rejoins_from_its_drop_pose(fault_run):
    res = fault_run
    summ, traj = res["summary"], res["traj"]
    col = {int(a): k for k, a in enumerate(traj["ids"])}[4]
    drop = _drop_event(summ, 4)
    rejoins = events_of(summ, EventKind.REJOIN, 4)
    assert len(rejoins) == 1, rejoins
    rj = rejoins[0]
    assert rj["pid"] == res["again"].pid, f"rejoin names pid {rj['pid']}, restarted pid {res['again'].pid}"
    assert rj["pid"] != res["pids"][4]
    kd, kr = drop["tick"], rj["tick"]
    print(f"\n[info] agent 4 dropped at tick {kd}, rejoined at tick {kr} of {summ['ticks']}")
    assert kd < kr < summ["ticks"], (kd, kr)
    assert traj["alive"][:kd, col].all()
    assert not traj["alive"][kd:kr, col].any()
    assert traj["alive"][kr:, col].all(), "agent 4 is not alive from its rejoin to the end"
    # "leave": frozen while gone, and back in the world exactly where it dropped.
    for key in ("x", "y", "heading"):
        a = traj[key][kd : kr + 1, col]
        assert (a == a[0]).all(), f"agent 4's {key} changed while it was gone"
    pose_drop = [traj[k][kd, col] for k in ("x", "y", "heading")]
    pose_rejoin = [traj[k][kr, col] for k in ("x", "y", "heading")]
    assert pose_drop == pose_rejoin
    assert traj["x"][kr + 2, col] != pose_rejoin[0] or traj["y"][kr + 2, col] != pose_rejoin[1], (
        "agent 4 does not move after rejoining"
    )
    # It is controlled again: commands after the rejoin, and its pinned follower 5 returns to it.
    assert summ["agents"]["4"]["pid"] == res["again"].pid
    back = [e for e in events_of(summ, EventKind.SWITCH, 5) if e["tick"] >= kr and e["to"] == 4]
    assert back and back[0]["tick"] <= kr + 1, f"follower 5 did not return to 4 after its rejoin: {back}"
    # The restarted process ended with the run.
    assert res["again_rc"] == 0, res["again"].text()


# --- 6. duplicate and unknown ids ---------------------------------------------------------------------
def _world_by_hand(rt, tmp_path, scenario: str, *extra):
    """A `swarm world` started here, once it listens: (process, endpoint, run id, observer)."""
    endpoint = f"unixsock-stream/{rt.dir}/w.sock"
    run_id = "byhand"
    w = rt.tracker.spawn(
        swarm_cmd(
            "world",
            SCENARIOS / scenario,
            "--listen",
            endpoint,
            "--run",
            run_id,
            "--out",
            tmp_path / "world-out",
            "--no-plots",
            *extra,
        ),
        "world",
    )
    return w, endpoint, run_id, observe_world(rt.tracker, w, endpoint, run_id)


def test_duplicate_and_unknown_ids_are_refused(rt, tmp_path):
    w, ep, run_id, world = _world_by_hand(rt, tmp_path, "case2.toml", "--join-timeout", "600")
    first = rt.tracker.spawn(agent_cmd(1, ep, run_id), "agent-1")
    world.wait(
        lambda i: agent_info(i, 1)["alive"], DEADLINE, "agent 1 to join", check=lambda: w.check_running("a join")
    )

    dup = rt.tracker.spawn(agent_cmd(1, ep, run_id), "agent-1-dup")
    rc = dup.wait(DEADLINE)
    assert rc == ExitCode.REFUSED, f"second agent 1 exited {rc}: {dup.text()}"
    assert "already live" in dup.text() and f"pid {first.pid}" in dup.text(), dup.text()

    # The same through the CLI, and with the run id looked up on the endpoint.
    dup2 = rt.tracker.spawn(swarm_cmd("agent", "--id", 1, "--connect", ep), "agent-1-dup-cli")
    assert dup2.wait(DEADLINE) == ExitCode.REFUSED and "already live" in dup2.text(), dup2.text()

    unknown = rt.tracker.spawn(agent_cmd(99, ep, run_id), "agent-99")
    rc = unknown.wait(DEADLINE)
    assert rc == ExitCode.REFUSED, f"agent 99 exited {rc}: {unknown.text()}"
    assert "not in scenario" in unknown.text(), unknown.text()

    # The live agent 1 was not disturbed, and nobody else joined.
    assert first.poll() is None
    info = world.info()
    one = agent_info(info, 1)
    assert (one["alive"], one["joins"], one["drops"]) == (True, 1, 0), one
    assert [a["id"] for a in info["agents"].values() if a["joins"]] == [1] and "99" not in info["agents"]

    w.group.signal(signal.SIGTERM)
    assert w.wait(DEADLINE) == ExitCode.TERMINATED, w.text()[-2000:]
    rc1 = first.wait(DEADLINE)
    print(f"\n[info] agent 1 exited {rc1} after the world was stopped with SIGTERM")
    assert rc1 in (0, 4), f"agent 1 exited {rc1} when the world stopped: {first.text()}"
    rt.tracker.assert_none_left(timeout=DEADLINE)
    summ = json.loads((tmp_path / "world-out" / "summary.json").read_text())
    assert [e["agent"] for e in events_of(summ, EventKind.JOIN)] == [1] and not events_of(summ, EventKind.DROP, 1), (
        summ["events"]
    )


# --- 8. the world vanishes ------------------------------------------------------------------------------
def test_agents_exit_when_the_world_vanishes(rt, tmp_path):
    w, ep, run_id, world = _world_by_hand(rt, tmp_path, "turtlebot.toml", "--duration", "4000", "--join-timeout", "120")
    agents = {i: rt.tracker.spawn(agent_cmd(i, ep, run_id), f"agent-{i}") for i in (1, 2)}
    world.wait(
        lambda i: has_started(i) and i["tick"] > 0,
        DEADLINE,
        "the run to start and tick",
        check=lambda: w.check_running("the run to start"),
    )
    world.close()
    t0 = time.monotonic()
    w.group.signal(signal.SIGKILL)
    exits = {}

    def all_exited() -> bool:
        for i, a in agents.items():
            if i not in exits and a.poll() is not None:
                exits[i] = time.monotonic() - t0
        return len(exits) == len(agents)

    wait_until(all_exited, DEADLINE, interval=0.005)
    print(
        "\n[timing] world SIGKILL -> agents exit: "
        + ", ".join(f"{i}: {1000 * s:.0f} ms" for i, s in sorted(exits.items()))
    )
    assert w.wait(DEADLINE) == -signal.SIGKILL
    for i, a in agents.items():
        assert i in exits, f"agent {i} still running {DEADLINE:g} s after the world died"
        assert a.poll() == ExitCode.WORLD_GONE, f"agent {i} exited {a.poll()}: {a.text()}"
        assert "vanished" in a.text(), a.text()  # the lifeline, not the grace of a silent world
    rt.tracker.assert_none_left(timeout=DEADLINE)


# case2 through lockstep `swarm up` for the stalls below: long enough for a stall to land mid-run
STALL_RUN_S = 10.0


# --- a frozen world: lockstep stays lockstep (docs/guides/faults.md#lockstep-under-stalls) ---------------
def test_a_world_stopped_5_s_mid_run_still_equals_sim(rt, tmp_path, shipped_sim):
    """SIGSTOP to the world for 5 s mid-run: its stall is not the agents' (no missed tick),
    the tick's frames go again, and the run equals `swarm sim` to the bit, reproducible."""
    # 10 s (1000 ticks): the stop lands once the world ticks (a few ms later), and the stalled
    # world cannot end the run meanwhile (deadline_restarts below says the stall was mid-run).
    up, _, _ = start_ticking(rt.tracker, tmp_path / "run", STALL_RUN_S)
    world = rt.tracker.world_pid(up.launcher)
    os.kill(world, signal.SIGSTOP)
    try:
        time.sleep(5.0)  # the fault itself; nothing is timed
    finally:
        os.kill(world, signal.SIGCONT)
    summ, traj = up.results(180)
    # the first 10 s of the session's `swarm sim` run of case2 (conftest.shipped_sim; in this
    # process, after the stop: on a loaded machine a sim during it could outlast the agents'
    # 10 s of --world-grace)
    res, sim_out = shipped_sim("case2")
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    ticks = round(STALL_RUN_S / 0.01)
    sim, _ = first_ticks(*sim_results(sim_out), ticks)
    assert summ["ticks"] == ticks
    for key in ("t", "x", "y", "heading", "out", "alive"):
        np.testing.assert_array_equal(traj[key], sim[key], err_msg=key)
    # the commands: every row but the last (a run's last row has none; the whole run's goes on)
    np.testing.assert_array_equal(traj["u"][:-1], sim["u"][:-1], err_msg="u")
    assert summ["reproducible"] is True, summ["not_reproducible"]
    assert all(a["missed_ticks"] == 0 and a["drops"] == 0 for a in summ["agents"].values()), summ["agents"]
    assert summ["deadline_restarts"] >= 1, "the world did not notice its own stall"


# --- 9. a frozen agent ----------------------------------------------------------------------------
def test_frozen_agent_is_dropped(rt, tmp_path):
    # 1000 ticks: the freeze lands once the world ticks (a few ms later), and the world, waiting
    # for the frozen agent's command, cannot end the run before it drops it.
    up, pids, _ = start_ticking(rt.tracker, tmp_path / "run", STALL_RUN_S)
    victim = pids[3]
    t_stop = time.time()
    os.kill(victim, signal.SIGSTOP)
    try:
        # lockstep holds a lost token LINK_GRACE s (a starved link may come back) before the drop
        up.wait_info(lambda i: agent_info(i, 3)["drops"], DEADLINE, "the world to drop the frozen agent 3")
        t_seen = time.time()
    finally:
        os.kill(victim, signal.SIGCONT)
    summ, traj = up.results(120)
    drops = events_of(summ, EventKind.DROP)
    assert drops and drops[0]["agent"] == 3, drops
    latency = drops[0]["wall_time"] - t_stop
    print(f"\n[timing] SIGSTOP agent 3 -> drop event {latency:.3f} s (seen live after {t_seen - t_stop:.3f} s)")
    assert latency > 0 and summ["reproducible"] is False, summ.get("not_reproducible")
    # Nobody else was dropped while the world waited for the frozen one.
    assert {e["agent"] for e in drops} == {3}, drops
    assert summ["completed"] is True
    check_time_column(traj, summ["ticks"], 0.01)
    col = {int(a): k for k, a in enumerate(traj["ids"])}[3]
    k = drops[0]["tick"]
    assert traj["alive"][:k, col].all()
    # After SIGCONT the process may come back briefly (its link reconnects and its token
    # reappears: a rejoin and another drop), but it must not outlive the run.
    after = [
        (e["kind"], e["tick"])
        for e in summ["events"]
        if e["agent"] == 3 and e["tick"] >= k and e["kind"] != EventKind.SWITCH
    ]
    log = up.out.joinpath("logs", "agent-3.log").read_text().strip()
    print(f"[info] agent 3 after SIGCONT: events {after}, log: {log!r}")
    rep_out, rep_alive = replay_events(summ["events"], traj["ids"], summ["ticks"] + 1)
    np.testing.assert_array_equal(traj["alive"], rep_alive)
    np.testing.assert_array_equal(traj["out"], rep_out)
