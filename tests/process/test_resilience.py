"""Resilience (issue "Resilience"): scripted faults, a kill/restart soak, rooted selection
against follower-only cycles, hostile input on every key, rogue commands.

Real processes over real zenoh (see tests/support/runtime_helpers.py: every process is tracked,
every wait has a deadline, each test kills only what it started and asserts that nothing
is left). The hostile-input tests open their own zenoh client session in this test
process, as a stranger on the run's bus would, always after the processes of the test
are started and closed in a `finally`; processes are only ever started with
subprocess (fork + exec).

Runtime bugs found while writing these tests are kept as regression tests at the end of
the file (a malformed fault notice, garbage after a frame, truth of an unknown agent). Tests
that only differ by the hostile input they send share one run (module fixtures): the forged
commands and the garbage on a sense key one lockstep run equal to `swarm sim`'s (`hostile_run`);
the launcher's two regression tests and the 10,000 malformed messages one realtime run
(`stranger_run`), which must outlive them all and stop with 130.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from cli_invoke import invoke
from deadlines import DEADLINE
from malformed import (
    ADMIN_BAD,
    BAD_JSON,
    CASE2_IDS,
    CASE2_LEADERS,
    CONTROL_BAD,
    CTL_BAD,
    EVENTS_BAD,
    JOIN_BAD,
    MIB,
    NON_IDS,
    _cmd_bad,
    _j,
    _oversized,
    _sense_bad,
    _truth_bad,
)
from runtime_helpers import (
    SCENARIOS,
    Runtime,
    agent_info,
    check_time_column,
    events_of,
    first_ticks,
    open_hub,
    open_session,
    replay_events,
    sim_results,
    start_up,
    swarm_cmd,
    wait_for,
)

from swarm.contracts import wire
from swarm.contracts.graph import analyse
from swarm.contracts.vocabulary import ExitCode
from swarm.world.recording import add_state_seconds

pytestmark = pytest.mark.slow

BAND = 0.02  # the 2% settling band of the recovery figures


# --- small helpers ------------------------------------------------------------------------------
def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _fault_event(summ: dict, index: int) -> dict:
    evs = [e for e in summ["events"] if e["kind"] == "fault" and e.get("fault", {}).get("index") == index]
    assert len(evs) == 1, f"fault {index}: fault events {evs}"
    return evs[0]


def _first_event(summ: dict, kind: str, agent: int, lo: int, hi: int) -> dict | None:
    """The first `kind` event of `agent` with lo <= tick < hi."""
    for e in events_of(summ, kind, agent):
        if lo <= e["tick"] < hi:
            return e
    return None


def _realtime_case2(rt, tmp_path):
    """case2 under `swarm up` (realtime, 600 s), once started: (run, run id, endpoint, agent pids)."""
    up = start_up(rt.tracker, SCENARIOS / "case2.toml", tmp_path / "run", "--clock", "realtime", "--duration", "600")
    run_id, endpoint = up.banner()
    up.wait_started(DEADLINE)
    agents = rt.tracker.wait_agent_pids(up.launcher, 6)
    return up, run_id, endpoint, agents


def _stop(up, sig=signal.SIGINT, timeout=DEADLINE) -> int:
    os.kill(up.launcher.pid, sig)
    return up.launcher.wait(timeout)


def assert_equals_sim_prefix(traj: dict, sim_traj: dict, sim_summ: dict, ticks: int, label: str) -> None:
    """The `swarm up` run `traj` is the first `ticks` ticks of the whole `swarm sim` run: positions
    to 1e-9 m (the distance printed after `label`), out-neighbours, alive and missed exactly."""
    sim_traj, _ = first_ticks(sim_traj, sim_summ, ticks)
    assert traj["x"].shape == sim_traj["x"].shape
    dist = max(np.max(np.abs(traj["x"] - sim_traj["x"])), np.max(np.abs(traj["y"] - sim_traj["y"])))
    print(f"{label}: max |dx|, |dy| = {dist:.3g} m")
    assert dist < 1e-9
    for key in ("out", "alive", "missed"):
        np.testing.assert_array_equal(traj[key], sim_traj[key], err_msg=key)


# --- 1. scenarios/faults.toml: one fault of each kind -------------------------------------------
# Every fault is over by t = 65 s (the noise, 60-65 s) and the whole run's last event is at t = 60 s:
# the first 66 s of the 200 s scenario hold every fault and every event. Each fault's window ends at
# the next fault, the last's (the noise's) at the end of the run: the seven windows that end inside
# the 66 s are the whole run's, fault for fault (no recovery in any: the next fault comes first), and
# the noise's recovery ends at t = 91.33 s, which, with the convergence (max relative error 3e-5 at
# 200 s), the session's whole `swarm sim` run of faults.toml shows (checked here, and in
# tests/pure/test_cli_offline.py). Lockstep `swarm up` equals `swarm sim` on any prefix.
FAULTS_DURATION = 66.0


def test_faults_toml_through_up(rt, tmp_path, shipped_sim):
    ticks = round(FAULTS_DURATION / 0.01)
    scen, dur = SCENARIOS / "faults.toml", f"{FAULTS_DURATION:g}"
    up = start_up(rt.tracker, scen, tmp_path / "run", "--clock", "lockstep", "--duration", dur)
    t0 = time.monotonic()
    summ, traj = up.results(240)
    wall = time.monotonic() - t0
    assert summ["completed"] is True and summ["ticks"] == ticks
    check_time_column(traj, ticks, 0.01)

    faults = summ["faults"]
    kinds = ["kill", "restart", "freeze", "thaw", "partition", "loss", "delay", "noise"]
    assert [f["kind"] for f in faults] == kinds
    print(f"\n[faults.toml] swarm up lockstep, first {FAULTS_DURATION:g} s: {wall:.1f} s wall; per fault:")
    for f in faults:
        print(
            f"  {f['kind']:<9} agent {str(f.get('agent')):<4} tick {f['tick']:>5}: recovery_time "
            f"{f['recovery_time']} s (window to {f['window_end_time']} s), worst relative error "
            f"{f['worst_relative_error']:.3f}, commands missed {f['commands_missed']}, switches {f['switches']}"
        )
    for i, f in enumerate(faults):
        assert f["index"] == i and f["tick"] == round(f["at"] / 0.01)
        ev = _fault_event(summ, i)
        assert ev["tick"] == f["tick"] and ev["agent"] == f.get("agent"), ev
    assert not [e for e in summ["events"] if e["kind"] in ("fault_skipped", "fault_late")], summ["events"]

    by_kind = {f["kind"]: f for f in faults}
    # kill -> drop, restart -> rejoin (the world holds its clock until it has seen them)
    k_kill, k_restart = by_kind["kill"]["tick"], by_kind["restart"]["tick"]
    drop4 = _first_event(summ, "drop", 4, k_kill, k_restart)
    rejoin4 = _first_event(summ, "rejoin", 4, k_restart, by_kind["freeze"]["tick"])
    assert drop4 is not None and rejoin4 is not None, summ["events"]
    assert drop4["tick"] == k_kill and rejoin4["tick"] == k_restart, (drop4, rejoin4)
    # freeze -> drop (at the ~1 s link lease, with the clock held), thaw -> rejoin: on their ticks
    k_freeze, k_thaw = by_kind["freeze"]["tick"], by_kind["thaw"]["tick"]
    drop2 = _first_event(summ, "drop", 2, k_freeze, k_thaw)
    rejoin2 = _first_event(summ, "rejoin", 2, k_thaw, summ["ticks"] + 1)
    assert drop2 is not None, f"the frozen agent 2 was not dropped before the thaw: {events_of(summ, 'drop', 2)}"
    assert rejoin2 is not None, f"the thawed agent 2 did not rejoin: {events_of(summ, 'rejoin', 2)}"
    assert (drop2["tick"], rejoin2["tick"]) == (k_freeze, k_thaw), (drop2, rejoin2)
    assert len(events_of(summ, "drop")) == 2 and len(events_of(summ, "rejoin")) == 2, summ["events"]
    # The recording agrees with the events (alive and out columns).
    rep_out, rep_alive = replay_events(summ["events"], traj["ids"], summ["ticks"] + 1)
    np.testing.assert_array_equal(traj["alive"], rep_alive)
    np.testing.assert_array_equal(traj["out"], rep_out)
    col = {int(a): k for k, a in enumerate(traj["ids"])}
    assert not traj["alive"][drop4["tick"] : rejoin4["tick"], col[4]].any()

    # Network faults: the partition loses agent 1's frames for its 2 s (200 ticks), the
    # loss draws 30% of every frame and command.
    part = by_kind["partition"]
    n_part = round(part["duration"] / 0.01)
    assert part["commands_missed"] >= n_part, part
    assert (traj["missed"][part["tick"] : part["tick"] + n_part] >= 1).all()
    assert by_kind["loss"]["commands_missed"] > 0, by_kind["loss"]

    # One engine: every fault kind means the same in `swarm sim`, so the runs are equal.
    res, sim_out = shipped_sim("faults")  # the session's whole run of faults.toml (conftest)
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    sim_traj, sim_summ = sim_results(sim_out)
    assert max(e["tick"] for e in sim_summ["events"]) < ticks, "an event of the whole run is past the prefix"
    assert_equals_sim_prefix(traj, sim_traj, sim_summ, ticks, "  swarm up vs swarm sim")  # the same first 66 s
    # The windows that end inside the prefix are the whole run's, recovery and all; the last
    # (the noise's) ends with this run, before its recovery (at 91.33 s), which the whole run shows.
    sim_faults = sim_summ["faults"]
    inside = [f for f in sim_faults if f["window_end_time"] < FAULTS_DURATION]
    assert len(inside) == len(faults) - 1 and faults[:-1] == inside, (faults, sim_faults)
    last, last_sim = faults[-1], sim_faults[-1]
    assert last["window_end_time"] == FAULTS_DURATION < last_sim["window_end_time"], (last, last_sim)
    assert last_sim["recovery_time"] is not None, last_sim
    assert last["recovery_time"] is None and last["at"] + last_sim["recovery_time"] > FAULTS_DURATION, (last, last_sim)
    assert {k: v for k, v in last.items() if k not in ("window_end_time", "recovery_time")} == {
        k: v for k, v in last_sim.items() if k not in ("window_end_time", "recovery_time")
    }, (last, last_sim)

    # Every agent alive and following at the end of the prefix; the whole run (`swarm sim`, which
    # this run is the first 66 s of) recovers from the last fault and ends with every agent in the band.
    worst = max(a["relative_error"] for a in summ["agents"].values())
    worst_end = max(a["relative_error"] for a in sim_summ["agents"].values())
    print(
        f"  last fault recovered after {last_sim['recovery_time']} s "
        f"(t = {last['at'] + last_sim['recovery_time']:.2f} s, "
        f"swarm sim); worst relative error at t = {FAULTS_DURATION:g} s: {worst:.4f}, at the end of the whole run "
        f"({sim_summ['ticks'] * 0.01:g} s, swarm sim): {worst_end:.2g} (BAND {BAND})"
    )
    for aid, a in summ["agents"].items():
        assert a["alive"] and a["root"] is not None, (aid, a)
    for aid, a in sim_summ["agents"].items():
        assert a["relative_error"] < BAND, (aid, a)
    assert sim_summ["converged"] is True


# --- 2. soak: 10 kill/restart pairs at random ticks (kills in 20 s) ----------------------------------------------
SOAK_SEED = 4  # both leaders are down at once between t = 26.44 s and 29.67 s with this seed
SOAK_KILLS = (10.0, 30.0)  # s: the kills are drawn between these
# The scenario's: the last restart is at 29.30 s, back in the 2% band for good 96.03 s later (at
# 125.3 s, as in a 250 s run), every agent within 0.22% of its radius at 150 s.
SOAK_DURATION = 150.0
SOAK_UP_DURATION = 35.0  # what `swarm up` runs of it: every kill and restart, and 5 s more


def soak_faults(
    seed: int, ids=CASE2_IDS, leaders=CASE2_LEADERS, pairs=10, lo=SOAK_KILLS[0], hi=SOAK_KILLS[1], dt=0.01
) -> list[tuple[int, int, int]]:
    """(agent, kill tick, restart tick) x pairs: kills between lo and hi s, restart 1-4 s later,
    never two faults on one tick, never two kill/restart windows of one agent overlapping,
    at least one leader among the victims."""
    rng = random.Random(seed)
    while True:
        used: set[int] = set()
        busy: dict[int, list] = {i: [] for i in ids}
        out = []
        for _ in range(100_000):
            if len(out) == pairs:
                break
            a = rng.choice(ids)
            k = rng.randint(round(lo / dt), round(hi / dt))
            r = k + rng.randint(round(1.0 / dt), round(4.0 / dt))
            if k in used or r in used or any(k <= r0 and k0 <= r for k0, r0 in busy[a]):
                continue
            used |= {k, r}
            busy[a].append((k, r))
            out.append((a, k, r))
        if len(out) == pairs and any(a in leaders for a, _, _ in out):
            return sorted(out, key=lambda p: p[1])


def write_soak_scenario(path: Path, pairs, duration: float = SOAK_DURATION) -> Path:
    text = (SCENARIOS / "case2.toml").read_text()
    text, n = re.subn(r"(?m)^duration = [0-9.]+$", f"duration = {duration}", text)
    assert n == 1
    text = text.replace('name = "case2"', 'name = "soak"')
    for a, k, r in pairs:
        text += (
            f'\n[[faults]]\nat = {k / 100:.2f}\nkind = "kill"\nagent = {a}\n'
            f'\n[[faults]]\nat = {r / 100:.2f}\nkind = "restart"\nagent = {a}\n'
        )
    path.write_text(text)
    return path


@pytest.mark.timeout(420)
def test_soak_kills_and_restarts(rt, tmp_path):
    """The soak's first 35 s through lockstep `swarm up` (all 10 kills and restarts, each a drop
    and a rejoin on its tick) equal to the same run by `swarm sim`, bit for bit; the whole 150 s
    of it (`swarm sim`, the same engine) re-converges after the last restart."""
    pairs = soak_faults(SOAK_SEED)
    scen = write_soak_scenario(tmp_path / "soak.toml", pairs)
    ticks = round(SOAK_UP_DURATION / 0.01)
    assert len({t for _, k, r in pairs for t in (k, r)}) == 20
    assert {a for a, _, _ in pairs} & set(CASE2_LEADERS)
    assert max(r for _, _, r in pairs) < ticks - 500  # every restart 5 s before the end of the `swarm up` run
    sim = rt.tracker.spawn(swarm_cmd("sim", scen, "--out", tmp_path / "sim", "--no-plots"), "sim-soak")
    up = start_up(rt.tracker, scen, tmp_path / "run", "--clock", "lockstep", "--duration", f"{SOAK_UP_DURATION:g}")
    t0 = time.monotonic()
    summ, traj = up.results(360)
    wall = time.monotonic() - t0
    print(
        f"\n[soak] seed {SOAK_SEED}: 10 kill/restart pairs {pairs}\n[soak] swarm up: {wall:.1f} s wall "
        f"for {SOAK_UP_DURATION:g} s simulated ({summ['wall_time']:.1f} s ticking, world clock held "
        f"for restarts meanwhile)"
    )
    assert summ["completed"] is True and summ["ticks"] == ticks
    check_time_column(traj, ticks, 0.01)
    assert len(summ["faults"]) == 20
    assert not [e for e in summ["events"] if e["kind"] in ("fault_skipped", "fault_late")], summ["events"]

    # Every kill has its drop (before the restart), every restart its rejoin (before the next kill).
    for a, k, r in pairs:
        nxt = min([k2 for a2, k2, _ in pairs if a2 == a and k2 > r], default=ticks + 1)
        drop = _first_event(summ, "drop", a, k, r)
        rejoin = _first_event(summ, "rejoin", a, r, nxt)
        assert drop is not None, f"agent {a} killed at tick {k}: no drop before tick {r}: {events_of(summ, 'drop', a)}"
        assert rejoin is not None, (
            f"agent {a} restarted at tick {r}: no rejoin before tick {nxt}: {events_of(summ, 'rejoin', a)}"
        )
        print(
            f"  agent {a}: kill tick {k} -> drop tick {drop['tick']}; restart tick {r} -> rejoin tick "
            f"{rejoin['tick']} (pid {rejoin.get('pid')})"
        )
    assert len(events_of(summ, "drop")) == 10 and len(events_of(summ, "rejoin")) == 10
    for aid in CASE2_IDS:
        n = sum(1 for a, _, _ in pairs if a == aid)
        a = summ["agents"][str(aid)]
        assert (a["joins"], a["drops"]) == (1 + n, n), (aid, a)
    rep_out, rep_alive = replay_events(summ["events"], traj["ids"], ticks + 1)
    np.testing.assert_array_equal(traj["alive"], rep_alive)

    # One engine: the same soak by `swarm sim`, cut to the same 35 s, is the same run.
    assert sim.wait(DEADLINE) == ExitCode.OK, sim.text()[-3000:]
    sim_traj, sim_summ = sim_results(tmp_path / "sim")
    assert sim_summ["ticks"] == round(SOAK_DURATION / 0.01)
    label = f"[soak] swarm up vs swarm sim over {SOAK_UP_DURATION:g} s"
    assert_equals_sim_prefix(traj, sim_traj, sim_summ, ticks, label)

    # each fault's recovery window but the last ends at the next fault, inside the `swarm up` run
    def recoveries(faults: list[dict]) -> list:
        return [f["recovery_time"] for f in sorted(faults, key=lambda f: f["tick"])[:-1]]

    assert recoveries(summ["faults"]) == recoveries(sim_summ["faults"])

    # The whole soak re-converges after its last fault.
    last = max(sim_summ["faults"], key=lambda f: f["tick"])
    print(
        f"[soak] last fault: {last['kind']} agent {last['agent']} at {last['at']} s, recovery_time "
        f"{last['recovery_time']} s, worst relative error {last['worst_relative_error']:.3f}; at "
        f"t = {SOAK_DURATION:g} s worst relative error "
        f"{max(a['relative_error'] for a in sim_summ['agents'].values()):.2g} (swarm sim)"
    )
    assert last["recovery_time"] is not None, last
    assert sim_summ["converged"] is True, {k: v["relative_error"] for k, v in sim_summ["agents"].items()}


# --- 3. follower-only cycles: nearest flags them live, rooted never forms them ------------------
def test_nearest_selection_cycle_is_flagged_live(rt, tmp_path):
    text = (SCENARIOS / "rooted.toml").read_text()
    text, n = re.subn(r'(?m)^selection = "rooted"$', 'selection = "nearest"', text)
    assert n == 1
    scen = tmp_path / "nearest.toml"
    scen.write_text(text)
    up = start_up(rt.tracker, scen, tmp_path / "run", "--clock", "realtime", "--duration", "600")
    run_id, endpoint = up.banner()
    up.wait_started(DEADLINE)
    seen: list[dict] = []

    def cycle_flagged():
        # `swarm graph --json` in this process (no process start), on the run's runtime dir
        res = invoke("graph", "--json", "--connect", endpoint, "--run", run_id, env={"SWARM_RUNTIME_DIR": rt.dir})
        assert up.launcher.poll() is None, up.launcher.text()[-2000:]
        if res.exit_code != 0:
            return None
        g = json.loads(res.stdout)
        seen.append(g)
        return g if ([2, 5] in g["cycles"] and {2, 5} <= set(g["unrooted"])) else None

    t0 = time.monotonic()
    g = wait_for(cycle_flagged, DEADLINE, "swarm graph --json to flag the cycle [2, 5]", interval=0.2)
    print(
        f"\n[nearest] cycle {g['cycles']} flagged at tick {g['tick']} after {time.monotonic() - t0:.2f} s; "
        f"unrooted {g['unrooted']}, edges {g['edges']}"
    )
    assert g["roots"]["2"]["root"] is None and g["roots"]["5"]["root"] is None
    assert set(g["leaders"]) == {1} and set(g["nodes"]) == {1, 2, 3, 4, 5}
    assert [2, 5] in g["edges"] and [5, 2] in g["edges"]
    assert _stop(up) == 130, up.launcher.text()[-3000:]
    rt.tracker.assert_none_left(timeout=DEADLINE)
    assert up.summary()["completed"] is False


# The first 34 s of rooted.toml: nearest selection would pair followers 2 and 5 from tick 0 and 3
# and 4 from t = 31.93 s in follower-only cycles (sim of rooted.toml with selection = "nearest").
ROOTED_DURATION = 34.0


def test_rooted_selection_keeps_every_follower_rooted(rt, tmp_path, shipped_sim):
    """The first 34 s of rooted.toml through lockstep `swarm up`: every follower rooted, no cycle
    at any tick, where nearest selection forms both of its cycles (34 s holds the second, at
    31.93 s); and the run is the same prefix of `swarm sim`'s whole run (conftest.shipped_sim),
    every column, switch and follow state. (Convergence of the whole run:
    tests/pure/test_rooted.py under `swarm sim`, which lockstep `swarm up` equals.)"""
    ticks = round(ROOTED_DURATION / 0.01)
    up = start_up(
        rt.tracker,
        SCENARIOS / "rooted.toml",
        tmp_path / "run",
        "--clock",
        "lockstep",
        "--duration",
        f"{ROOTED_DURATION:g}",
    )
    res, sim_out = shipped_sim("rooted")  # meanwhile (or already run by the session)
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    sim_whole, sim_whole_summ = sim_results(sim_out)
    sim, sim_summ = first_ticks(sim_whole, sim_whole_summ, ticks)
    summ, traj = up.results(240)
    assert summ["completed"] is True and summ["ticks"] == ticks
    check_time_column(traj, ticks, 0.01)
    ids = [int(i) for i in traj["ids"]]
    leaders = {i for i, r in zip(ids, traj["role"]) if r == "leader"}
    final = analyse({i: (int(o) if o >= 0 else None) for i, o in zip(ids, traj["out"][-1])}, leaders)
    print(f"\n[rooted] final graph {final['edges']}, roots { {k: v['root'] for k, v in final['roots'].items()} }")
    assert final["cycles"] == [] and final["unrooted"] == [], final
    for aid, a in summ["agents"].items():
        assert a["root"] in leaders, (aid, a)
    # Loop-free at every tick of the run, not only at the end.
    rows = np.unique(traj["out"], axis=0)
    for row in rows:
        g = analyse({i: (int(o) if o >= 0 else None) for i, o in zip(ids, row)}, leaders)
        assert g["cycles"] == [], f"follower-only cycle {g['cycles']} in recorded graph {g['edges']}"
    # Lockstep `swarm up` of the rooted rule is `swarm sim`'s run (the agents choose in their own
    # processes, the sim's brains in one): every column, the switches, the follow states' seconds.
    for key in ("t", "x", "y", "heading", "out", "alive", "follow"):
        np.testing.assert_array_equal(traj[key], sim[key], err_msg=f"rooted: {key}")
    # the commands: every row but the last (a run's last row has none; the whole run's goes on)
    np.testing.assert_array_equal(traj["u"][:-1], sim["u"][:-1], err_msg="rooted: u")
    switches = [(e["tick"], e["agent"], e["from"], e["to"]) for e in summ["events"] if e["kind"] == "switch"]
    assert sorted(switches) == sorted(
        (e["tick"], e["agent"], e["from"], e["to"]) for e in sim_summ["events"] if e["kind"] == "switch"
    )
    expected_state_s: dict = {str(i): {} for i in ids}
    add_state_seconds(expected_state_s, sim, 0.01)
    for aid, a in summ["agents"].items():
        assert a.get("state_s") == expected_state_s[aid].get("state_s"), aid
        # no loss of an out-neighbour in the whole sim run (unlimited sensing), none in this one
        for key in ("losses", "loss_switches_max"):
            assert not a.get(key) and not sim_whole_summ["agents"][aid].get(key), (aid, key)


# --- 4. 10,000 malformed messages on every key -------------------------------------------------
# (the test is the last of this file: it sends them on the launcher regression tests' run, and ends it)
def garbage_plan(run: str, rng: random.Random) -> list[tuple[str, str, bytes]]:
    """10,000 (op, key or selector, payload): op put | get | token, over every key the runtime
    listens to. Nothing in it is a valid message that could change the run."""
    P = wire.run_prefix(run)
    some = CASE2_IDS + NON_IDS
    plan: list[tuple[str, str, bytes]] = []

    def add(n, make):
        for _ in range(n):
            plan.append(make())

    # Oversized payloads (> 1 MiB) on each kind of key, including well-formed requests that
    # are only invalid by their size (a pause, a KILL signal, an end notice).
    big = [("put", wire.agent_key(run, a, "cmd"), _oversized(rng)) for a in (1, 3, "abc")]
    big += [("put", wire.agent_key(run, a, "sense"), _oversized(rng)) for a in CASE2_IDS]
    big += [
        ("put", wire.agent_key(run, 2, "ctl"), _oversized(rng, b'{"v": 1, "kind": "signal", "signal": "KILL"}')),
        ("put", wire.agent_key(run, 5, "ctl"), _oversized(rng)),
        ("put", wire.world_control_key(run), _oversized(rng, b'{"v": 1, "kind": "end"}')),
        ("put", wire.world_control_key(run), _oversized(rng)),
        ("put", wire.events_key(run), _oversized(rng)),
        ("put", wire.truth_key(run), _oversized(rng)),
        ("get", wire.world_admin_key(run), _oversized(rng, b'{"v": 1, "cmd": "pause"}')),
        ("get", wire.world_admin_key(run), _oversized(rng)),
        ("get", wire.agent_key(run, 3, "join"), _oversized(rng)),
        ("get", wire.world_info_key(run), _oversized(rng)),
        ("get", wire.agent_key(run, 4, "status"), _oversized(rng)),
    ]
    plan += big
    n_small = 10_000 - len(big)
    counts = {
        "cmd": 3000,
        "sense": 2000,
        "ctl": 1000,
        "control": 700,
        "events": 400,
        "truth": 500,
        "admin": 800,
        "join": 500,
        "info": 300,
        "status": 400,
        "token": 400,
    }
    counts["cmd"] -= sum(counts.values()) - n_small  # the oversized ones are part of the 10,000
    add(counts["cmd"], lambda: (lambda k: ("put", wire.agent_key(run, k, "cmd"), _cmd_bad(rng, k)))(rng.choice(some)))
    add(
        counts["sense"],
        lambda: (lambda k: ("put", wire.agent_key(run, k, "sense"), _sense_bad(rng, k)))(
            rng.choice(CASE2_IDS * 4 + NON_IDS)
        ),
    )
    add(
        counts["ctl"],
        lambda: ("put", wire.agent_key(run, rng.choice(CASE2_IDS * 3 + NON_IDS), "ctl"), rng.choice(CTL_BAD)),
    )
    add(counts["control"], lambda: ("put", wire.world_control_key(run), rng.choice(CONTROL_BAD)))
    add(counts["events"], lambda: ("put", wire.events_key(run), rng.choice(EVENTS_BAD)))
    add(counts["truth"], lambda: ("put", wire.truth_key(run), _truth_bad(rng)))
    add(counts["admin"], lambda: ("get", wire.world_admin_key(run), rng.choice(ADMIN_BAD)))
    add(counts["join"], lambda: ("get", wire.agent_key(run, rng.choice(some), "join"), rng.choice(JOIN_BAD)))
    add(
        counts["info"],
        lambda: (
            "get",
            wire.world_info_key(run) + rng.choice(["", "?sensing=maybe", "?x=1;y", "?;;;", "?sensing=0;sensing=1"]),
            rng.choice(BAD_JSON),
        ),
    )
    add(counts["status"], lambda: ("get", wire.agent_key(run, rng.choice(some), "status"), rng.choice(BAD_JSON)))
    add(counts["token"], lambda: ("token", f"{P}/agent/{rng.choice([n for n in NON_IDS if n != '99'])}/alive", b""))
    rng.shuffle(plan)
    assert len(plan) == 10_000
    return plan


def send_garbage(ses, plan) -> dict:
    """Publish / query / declare everything in `plan`; returns counts."""
    stats = {"put": 0, "get": 0, "token": 0, "replies_ok": 0, "replies_err": 0, "bytes": 0}
    pending, tokens = [], []

    def drain():
        for h in pending:
            for r in h:
                stats["replies_ok" if r.ok is not None else "replies_err"] += 1
        pending.clear()

    for n, (op, key, payload) in enumerate(plan):
        stats[op] += 1
        stats["bytes"] += len(payload)
        if op == "put":
            ses.put(key, payload)
        elif op == "get":
            pending.append(ses.get(key, payload=payload, timeout=2.0))
            if len(pending) >= 32:
                drain()
        else:
            tokens.append(ses.liveliness().declare_token(key))
            if len(tokens) > 16:
                tokens.pop(0).undeclare()
        if n % 100 == 99:
            time.sleep(0.003)  # a stranger in a hurry, not one that drops its own messages
    drain()
    for t in tokens:
        t.undeclare()
    return stats


# --- 5. a stranger forging commands and flooding a sense key changes nothing ------------------------
HOSTILE_DURATION = 15.0  # s of case2 (1500 ticks): the stranger is on the bus for the whole run
HOSTILE_DEADLINE = 10.0  # s the world waits for a command in that run (case2: 0.5 s)


@pytest.fixture(scope="module")
def hostile_run(tmp_path_factory, shipped_sim):
    """case2 for 15 s through lockstep `swarm up` behind an open hub, with a stranger on its bus
    doing two things at once from the start of the run to its end: forging commands for agent 3
    on its cmd key (test_rogue_commands_change_nothing) and flooding agent 3's sense key with
    random bytes, for at most 10 s or until the world reports a missed tick of agent 3
    (test_garbage_on_sense_key_costs_no_frame). One run for both: each hostile input must leave
    the run equal to `swarm sim`'s, so both together must too. The run waits up to
    HOSTILE_DEADLINE for a command instead of case2's 0.5 s: the stranger's flood loads the
    machine, and a leader slowed past 0.5 s (not a hostile input's doing) would be held and
    counted as missed; a frame a hostile input costs is never answered, so it is still a missed
    tick, only a later one. Returns the results, what was sent, and the first 15 s of the
    session's `swarm sim` run of case2 (conftest.shipped_sim)."""
    base = tmp_path_factory.mktemp("hostile")
    ticks = round(HOSTILE_DURATION / 0.01)
    scenario = base / "case2.toml"  # case2 with a longer lockstep deadline (the same trajectory)
    text = (SCENARIOS / "case2.toml").read_text(encoding="utf-8")
    assert "\n[run]\n" in text and "lockstep_deadline" not in text
    scenario.write_text(
        text.replace("\n[run]\n", f"\n[run]\nlockstep_deadline = {HOSTILE_DEADLINE}\n", 1), encoding="utf-8"
    )
    with Runtime(base) as r:
        open_hub(r)  # the stranger gets in: what the world's own checks do behind the hub's
        up = start_up(
            r.tracker,
            scenario,
            base / "run",
            "--clock",
            "lockstep",
            "--duration",
            f"{HOSTILE_DURATION:g}",
        )
        run_id, endpoint = up.banner()
        ses = open_session(endpoint)
        rng_cmd, rng_sense = random.Random(7), random.Random(3)
        latest = [0]
        sent = {"rogue": 0, "sense": 0}

        def on_sense(sample):  # the rogue reads agent 3's frames to know the current tick
            try:
                latest[0] = wire.decode_sense(sample.payload.to_bytes()).tick
            except wire.WireError:
                pass

        def missed_now() -> int:
            info = up.info()
            return 0 if info is None else agent_info(info, 3)["missed"]

        try:
            sub = ses.declare_subscriber(wire.agent_key(run_id, 3, "sense"), on_sense)
            pub = ses.declare_publisher(wire.agent_key(run_id, 3, "cmd"), express=True)
            sense_key = wire.agent_key(run_id, 3, "sense")
            up.wait_started(DEADLINE)
            t0 = time.monotonic()
            flood_end, t_end = t0 + 10.0, t0 + 180
            while up.launcher.poll() is None and time.monotonic() < t_end:
                c = wire.Command(
                    3,
                    max(0, latest[0] - rng_cmd.randint(0, 2)),
                    rng_cmd.uniform(-5.0, 5.0),
                    rng_cmd.choice([None, 1, 2, 4, 5, 6]),
                    rng_cmd.choice(wire.PHASES),
                    rng_cmd.choice([None, 0, 1, 2, 7]),
                    rng_cmd.getrandbits(64),
                )
                pub.put(wire.encode_cmd(c))
                sent["rogue"] += 1
                if time.monotonic() < flood_end:
                    ses.put(sense_key, rng_sense.randbytes(16))
                    sent["sense"] += 1
                    if sent["sense"] % 500 == 0 and missed_now() > 0:
                        flood_end = 0.0  # a miss: the flood has shown what it had to
                time.sleep(0.0003)
            sub.undeclare()
        finally:
            ses.close()
        summ, traj = up.results(60)
    res, sim_out = shipped_sim("case2")
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    sim, _ = first_ticks(*sim_results(sim_out), ticks)
    return {"summ": summ, "traj": traj, "sim": sim, "sent": sent, "ticks": ticks}


def test_rogue_commands_change_nothing(hostile_run):
    summ, traj, sim = hostile_run["summ"], hostile_run["traj"], hostile_run["sim"]
    dx = np.max(np.abs(traj["x"] - sim["x"]))
    dy = np.max(np.abs(traj["y"] - sim["y"]))
    rogue = summ["agents"]["3"]["rogue_commands"]
    print(
        f"\n[rogue] {hostile_run['sent']['rogue']} forged commands for agent 3 published; the world counted "
        f"{rogue} rogue commands; max |dx| {dx:.3g} m, |dy| {dy:.3g} m against swarm sim; missed ticks "
        f"{[a['missed_ticks'] for a in summ['agents'].values()]}"
    )
    assert summ["completed"] is True and summ["ticks"] == hostile_run["ticks"]
    assert traj["x"].shape == sim["x"].shape
    assert dx < 1e-9 and dy < 1e-9, f"the rogue changed the trajectory: {max(dx, dy)} m"
    np.testing.assert_array_equal(traj["out"], sim["out"])
    assert rogue > 0
    rogue_events = events_of(summ, "rogue", 3)
    assert rogue_events and "claim key" in rogue_events[0]["reason"], rogue_events
    assert {e["agent"] for e in events_of(summ, "rogue")} == {3}


# --- regression tests for runtime bugs these tests found -------------------------------------------
def test_garbage_on_sense_key_costs_no_frame(hostile_run):
    """Random bytes on agent 3's sense key (hostile_run's flood) cost agent 3 no frame: it used
    to miss ticks under such a flood (each a 0.5 s deadline of the world)."""
    summ, traj, sim = hostile_run["summ"], hostile_run["traj"], hostile_run["sim"]
    missed = summ["agents"]["3"]["missed_ticks"]
    diff = max(np.max(np.abs(traj["x"] - sim["x"])), np.max(np.abs(traj["y"] - sim["y"])))
    print(
        f"\n[sense garbage] {hostile_run['sent']['sense']} random payloads on agent 3's sense key; agent 3 "
        f"counted {summ['agents']['3']['garbage']} garbage messages, missed {missed} ticks; max position "
        f"difference to sim {diff:.3g} m"
    )
    assert hostile_run["sent"]["sense"] > 0 and summ["agents"]["3"]["garbage"] > 0
    assert missed == 0 and diff < 1e-9


@pytest.fixture(scope="module")
def stranger_run(tmp_path_factory):
    """One realtime case2 under `swarm up` behind an open hub (a stranger's messages get in: the
    hub's checks are tested in tests/process/test_access.py), shared by the regression tests of
    the launcher below, each of which leaves it running, and by the 10,000 malformed messages
    (test_malformed_messages_on_every_key, last in this file), which stop it with Ctrl-C and read
    its summary: (run, run id, endpoint, agent pids). At the end (if still running) Ctrl-C: exit
    130 and no process left."""
    base = tmp_path_factory.mktemp("stranger")
    with Runtime(base) as r:
        open_hub(r)
        up, run_id, endpoint, agents = _realtime_case2(r, base)
        try:
            yield up, run_id, endpoint, agents
        finally:
            if up.launcher.poll() is None:
                assert _stop(up) == 130, up.launcher.text()[-3000:]
            else:
                up.launcher.wait(DEADLINE)


def _still_running(up, agents) -> None:
    assert up.launcher.poll() is None, f"swarm up exited {up.launcher.poll()}:\n{up.launcher.text()[-1500:]}"
    killed = [i for i, p in agents.items() if not _alive(p)]
    assert not killed, f"agents {killed} died"


@pytest.mark.parametrize(
    "fault", [{"agent": [4], "kind": "kill"}, {"agent": "a/b", "kind": "restart"}], ids=["list-agent", "path-agent"]
)
def test_launcher_survives_malformed_fault_notice(stranger_run, fault):
    up, run_id, endpoint, agents = stranger_run
    _still_running(up, agents)

    def dropped() -> int:  # how many notices the launcher has dropped, by its latest line about it
        said = re.findall(r"ignored a malformed fault notice \(.*; (\d+) so far\)", up.launcher.text())
        return int(said[-1]) if said else 0

    before = dropped()
    ses = open_session(endpoint)
    try:
        notice = _j({"v": 1, "kind": "fault", "index": "x", "fault": fault})

        def noted() -> bool:  # (sent again until noted: the run is shared, a put may precede its route)
            ses.put(wire.world_control_key(run_id), notice)
            return dropped() > before or up.launcher.poll() is not None

        # The launcher reads its notices every 0.25 s and says when it drops one (a line a second at most).
        wait_for(noted, DEADLINE, "the launcher to read and drop the malformed notice", interval=0.3)
    finally:
        ses.close()
    rc = up.launcher.poll()
    assert rc is None, f"swarm up exited {rc} on the notice {fault}:\n{up.launcher.text()[-600:]}"
    _still_running(up, agents)


def test_launcher_survives_truth_of_unknown_agent(stranger_run):
    """Well-formed ground truth with an agent the scenario file does not have (what the world
    itself sends once `swarm spawn` adds one, or a stranger on the truth key): the launcher's
    progress line skips it. (It used to raise KeyError in Launcher.progress and end the run.)"""
    up, run_id, endpoint, agents = stranger_run
    _still_running(up, agents)
    ids = np.array([1, 99])
    buf = wire.encode_truth(
        5,
        0.05,
        ids,
        np.array([28.0, 10.0]),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        np.array([-1, 1]),
        ["active", "active"],
    )
    ses = open_session(endpoint)
    sent = 0
    try:
        t_end = time.monotonic() + 3.0  # the launcher reads the latest truth 4 times a second
        while time.monotonic() < t_end and up.launcher.poll() is None:
            ses.put(wire.truth_key(run_id), buf)
            sent += 1
            time.sleep(0.001)
    finally:
        ses.close()
    tick = up.progress_tick()
    assert up.launcher.poll() is None, (
        f"swarm up exited {up.launcher.poll()} after {sent} forged truth messages:\n{up.launcher.text()[-1500:]}"
    )
    wait_for(lambda: up.progress_tick() > tick, DEADLINE, "the launcher's progress after the forged truth")
    _still_running(up, agents)


# The last test on the stranger's run (stranger_run): it ends the run, and checks its summary.
def test_malformed_messages_on_every_key(stranger_run):
    up, run_id, endpoint, agents = stranger_run  # a stranger sends it: behind the hub's checks (test_access.py)
    tracker = up.tracker
    _still_running(up, agents)
    world = tracker.world_pid(up.launcher)
    assert world is not None
    plan = garbage_plan(run_id, random.Random(20240601))
    ses = open_session(endpoint)
    t0 = time.monotonic()
    try:
        stats = send_garbage(ses, plan)
    finally:
        ses.close()
    send_s = time.monotonic() - t0
    print(
        f"\n[garbage] sent {sum(stats[k] for k in ('put', 'get', 'token'))} malformed messages "
        f"({stats['put']} puts, {stats['get']} queries, {stats['token']} liveliness tokens, "
        f"{stats['bytes'] / MIB:.1f} MiB) in {send_s:.1f} s; replies {stats['replies_ok']} ok, "
        f"{stats['replies_err']} errors"
    )
    assert stats["put"] + stats["get"] + stats["token"] == 10_000

    # Every process of the run is still alive (no agent restarted or added), the run still ticks.
    time.sleep(0.5)
    assert up.launcher.poll() is None, up.launcher.text()[-3000:]
    tracker.poll_once()
    dead = [f"agent {i} (pid {p})" for i, p in agents.items() if not _alive(p)]
    dead += [] if _alive(world) else [f"world (pid {world})"]
    assert not dead, f"processes died under garbage: {dead}\n{up.world_text()[-3000:]}"
    assert tracker.agent_pids(up.launcher) == agents, "the launcher started agent processes"
    live = up.observe().live
    info1, st1 = live.info(), live.statuses()
    info2 = wait_for(
        lambda: (i := live.info())["tick"] - info1["tick"] > 30 and i, DEADLINE, "the run ticking on after the garbage"
    )
    st2 = live.statuses()
    assert info2["paused"] is False
    assert all(a["alive"] for a in info2["agents"].values()), info2["agents"]
    assert info2["garbage"] > 0
    assert set(st1) == set(st2) == set(CASE2_IDS), (sorted(st1), sorted(st2))
    garbage = {i: st2[i]["garbage"] for i in CASE2_IDS}
    print(
        f"[garbage] world info: garbage {info2['garbage']}, ignored {info2['ignored']}; "
        f"agents' own garbage counts {garbage}; world per-agent garbage "
        f"{ {k: a['garbage'] for k, a in info2['agents'].items()} }"
    )
    for i in CASE2_IDS:
        assert st2[i]["garbage"] > 0, (i, st2[i])
        assert st2[i]["last_tick"] > st1[i]["last_tick"], f"agent {i} stopped answering its frames"
    # Nobody dropped or added, no pause (the summary's events say the same for the whole run, below).
    assert set(info2["agents"]) == {str(i) for i in CASE2_IDS}
    assert not [a for a in info2["agents"].values() if a["drops"]], info2["agents"]

    assert _stop(up) == 130, up.launcher.text()[-3000:]
    tracker.assert_none_left(timeout=DEADLINE)
    summ = up.summary()
    print(
        f"[garbage] summary: garbage_messages {summ['garbage_messages']}, ignored_messages "
        f"{summ['ignored_messages']}, per agent { ({k: a['garbage'] for k, a in summ['agents'].items()}) }"
    )
    assert summ["garbage_messages"] > 0
    assert summ["garbage_messages"] >= info2["garbage"]
    assert set(summ["agents"]) == {str(i) for i in CASE2_IDS}
    for aid, a in summ["agents"].items():
        assert isinstance(a["garbage"], int) and a["garbage"] >= 0, (aid, a)
        assert a["alive"] and a["joins"] == 1 and a["drops"] == 0, (aid, a)
    # a flood of join claims is rate-limited (one `limit` event, counted): nothing else happened
    # (but `late`: on a loaded machine the realtime clock can stall, the machine's doing, not the garbage's)
    assert {e["kind"] for e in summ["events"]} <= {"join", "start", "switch", "limit", "late"}, sorted(
        {e["kind"] for e in summ["events"]}
    )
    assert set(summ["over_limit"]) <= {"join_rate"}, summ["over_limit"]
    assert [e["limit"] for e in summ["events"] if e["kind"] == "limit"] == list(summ["over_limit"])
