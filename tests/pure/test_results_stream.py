"""A run's results written by streaming its recording (world/results_stream.py): the same
trajectory.npz and summary.json as the all-in-memory way (`recording_arrays(read_recording())`
then np.savez_compressed and `RunResult.summary`), to the bit, and memory that does not grow
with the run's length (tracemalloc, not timed)."""

from __future__ import annotations

import json
import tracemalloc
import zipfile
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from swarm.contracts.scenario import Scenario, load_scenario
from swarm.contracts.scenario_tables import AgentSpec
from swarm.contracts.vocabulary import FollowState
from swarm.contracts.wire import FOLLOW_STATES
from swarm.offline.sim import run_sim
from swarm.world import results_stream
from swarm.world.recording import (
    RECORDING_FILE,
    SUMMARY_FILE,
    TRAJECTORY_FILE,
    RunResult,
    StreamRecorder,
    _Loaded,
    _write_streamed,
    recording_arrays,
    recover_run,
    write_run,
)
from swarm.world.stream import StreamWriter, read_recording

ROOT = Path(__file__).resolve().parents[2]
FAULTS = ROOT / "scenarios" / "faults.toml"


def old_write(path: Path, out: Path, scenario: Scenario | None = None, events=None, extra=None, agent_extra=None):
    """The results as write_run wrote them before streaming: every tick row in memory."""
    rec = read_recording(path)
    res = RunResult(scenario or rec.scenario, _Loaded(recording_arrays(rec)), rec.events if events is None else events)
    res.extra.update(extra or {})
    res.agent_extra.update(agent_extra or {})
    return write_run(res, out)


def members(npz: Path) -> list[tuple[str, bytes]]:
    """Each member of the zip, decompressed: the .npy header and data, byte for byte."""
    with zipfile.ZipFile(npz) as z:
        return [(i.filename, z.read(i.filename)) for i in z.infolist()]


def assert_same_results(a: Path, b: Path) -> None:
    ma, mb = members(a / TRAJECTORY_FILE), members(b / TRAJECTORY_FILE)
    assert [n for n, _ in ma] == [n for n, _ in mb]
    for (name, x), (_, y) in zip(ma, mb):
        assert x == y, name
    with zipfile.ZipFile(a / TRAJECTORY_FILE) as z:
        assert all(i.compress_type == zipfile.ZIP_DEFLATED for i in z.infolist())
    assert (a / SUMMARY_FILE).read_bytes() == (b / SUMMARY_FILE).read_bytes()


def synthetic(
    path: Path, s: Scenario, ticks: int, seed: int = 1, quirks: bool = True, flush_every: int = 200, switch_every=37
) -> None:
    """A recording with made-up ticks: orbits near the expected radii with noise, followers
    switching, dying and rejoining now and then; with `quirks`, what the reader must get right:
    a tick written twice (at once, and again much later), an agent added at run time, rows
    whose ids are not in the scenario's order, and ticks after a gap (not rows)."""
    rng = np.random.default_rng(seed)
    w = StreamWriter(path, s, ticks)
    ids = list(s.ids)
    leaders = [a.id for a in s.agents if a.role == "leader"]
    tx, ty = s.target.x, s.target.y
    n = len(ids)
    out = np.array([-1 if a.role == "leader" else leaders[0] for a in s.agents], dtype=np.int64)
    alive = np.ones(n, dtype=bool)
    follow = rng.integers(0, len(FOLLOW_STATES), n).astype(np.int8)
    phase = rng.uniform(0, 2 * np.pi, n)
    radius = np.array([a.speed for a in s.agents], dtype=float)

    def row(k: int):
        t = k * s.run.dt
        r = radius[: len(ids)] * (1 + 0.5 * np.exp(-k / 150) + 0.002 * rng.standard_normal(len(ids)))
        th = phase[: len(ids)] + t * (1 + 0.01 * rng.standard_normal(len(ids)))
        x, y = tx + r * np.cos(th), ty + r * np.sin(th)
        x[rng.random(len(ids)) < 0.002] = np.nan
        return t, x, y, th + np.pi / 2, rng.standard_normal(len(ids)), int(rng.integers(0, 3))

    def log(k: int, order=None):
        t, x, y, h, u, missed = row(k)
        o = np.arange(len(ids)) if order is None else order
        w.tick(k, t, np.array(ids)[o], x[o], y[o], h[o], u[o], out[o], alive[o], missed, follow[o])

    for k in range(ticks + 1):
        if k and rng.random() < 0.02:  # a follower switches, to another agent or to none
            j = int(rng.integers(0, len(ids)))
            if ids[j] not in leaders:
                out[j] = int(rng.choice([-1, *[i for i in ids if i != ids[j]]]))
        if k and rng.random() < 0.05:  # somebody's follow state changes
            follow[int(rng.integers(0, len(ids)))] = int(rng.integers(0, len(FOLLOW_STATES)))
        if k and rng.random() < 0.01:  # a follower drops or rejoins
            j = int(rng.integers(0, len(ids)))
            if ids[j] not in leaders:
                alive[j] = not alive[j]
        if quirks and k == ticks // 3:  # an agent added at run time
            spec = AgentSpec(id=99, role="follower", x=1.0, y=2.0, heading=0.0, speed=12.0)
            w.add_agent(spec, k * s.run.dt)
            ids.append(99)
            out, alive = np.append(out, leaders[-1]), np.append(alive, True)
            follow = np.append(follow, np.int8(2))
            phase, radius = np.append(phase, 0.3), np.append(radius, 12.0)
            w.event({"kind": "join", "agent": 99, "tick": k, "time": k * s.run.dt})
        order = np.arange(len(ids))[::-1] if quirks and k % 97 == 5 else None
        log(k, order)
        if quirks and k == 50:
            log(k)  # the same tick again, at once: the later counts
        if quirks and k == ticks // 2:
            for again in range(10, 14):  # earlier ticks again, much later: the later counts
                log(again)
        if k % switch_every == 0:
            w.event({"kind": "switch", "agent": ids[-1], "tick": k, "time": k * s.run.dt})
        if k % flush_every == 0:
            w.flush()
    if quirks:
        log(ticks)  # the final row written twice
        log(ticks + 3)  # after a gap: not a row
    w.close()


def faults_scenario(dt: float = 0.1) -> Scenario:
    """faults.toml with a coarser dt: its faults (20..60 s) within a few hundred ticks."""
    s = load_scenario(FAULTS)
    return s.model_copy(update={"run": s.run.model_copy(update={"dt": dt})})


@pytest.mark.slow
@pytest.mark.parametrize("chunk", [7, 64, 4096])
def test_streamed_results_equal_the_memory_results_on_a_synthetic_recording(tmp_path, monkeypatch, chunk):
    monkeypatch.setattr(results_stream, "CHUNK", chunk)
    s = faults_scenario()
    rec = tmp_path / RECORDING_FILE
    synthetic(rec, s, 800)
    new, old = tmp_path / "new", tmp_path / "old"
    new.mkdir()
    (new / RECORDING_FILE).write_bytes(rec.read_bytes())
    summ = recover_run(new)  # what `swarm export` does
    assert summ["faults"] and summ["switches"] > 0 and "99" in summ["agents"] and summ["ticks"] == 800
    extra = {"engine": "recovered", "complete": False, "recording_finished": True, "completed": False}
    old_write(rec, old, extra=extra)  # recover_run as it was
    assert_same_results(new, old)
    assert not list(new.glob(".results-*"))  # the temporary files are gone


@pytest.mark.slow
def test_streamed_arrays_equal_the_memory_arrays(tmp_path, monkeypatch):
    monkeypatch.setattr(results_stream, "CHUNK", 5)
    s = faults_scenario()
    rec = tmp_path / RECORDING_FILE
    synthetic(rec, s, 300, seed=4)
    sr = StreamRecorder.__new__(StreamRecorder)  # only its arrays(): the recording is written
    sr.path, sr._arrays, sr.memory = rec, None, None
    sr.writer = type("Closed", (), {"close": lambda self: None})()
    a, b = sr.arrays(), recording_arrays(read_recording(rec))
    assert list(a) == list(b)
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and a[k].tobytes() == b[k].tobytes(), k


def test_a_run_without_faults_and_a_short_one(tmp_path):
    """No faults (no recovery windows), and runs of 1 and 2 rows."""
    s = load_scenario(ROOT / "scenarios" / "case2.toml")
    for ticks in (0, 1, 150):
        d = tmp_path / str(ticks)
        d.mkdir()
        rec = d / RECORDING_FILE
        synthetic(rec, s, ticks, quirks=False)
        old = d / "old"
        old.mkdir()
        old_write(rec, old, s, extra={"engine": "x"})
        new = d / "new"
        new.mkdir()
        res = RunResult(s, _Finished(rec), read_recording(rec).events, {"engine": "x"})
        write_run(res, new)
        assert_same_results(new, old)


def test_an_older_recording_without_follow_states_reads_as_none(tmp_path, monkeypatch):
    """A swarm-tick-v1 recording (before the follow states: no `follow` bytes) gives the same
    results as ever, with `follow` all none and each follower's `state_s` all none."""
    from swarm.world import stream

    v2 = stream.encode_tick

    def v1(*args, **kw) -> bytes:
        data = v2(*args, **kw)
        return data[: -len(args[2])]  # without the n follow bytes

    monkeypatch.setattr(stream, "encode_tick", v1)
    s = load_scenario(ROOT / "scenarios" / "case2.toml")
    rec = tmp_path / RECORDING_FILE
    synthetic(rec, s, 120)
    assert len(read_recording(rec).rows[0]["follow"]) == len(s.ids)
    old, new = tmp_path / "old", tmp_path / "new"
    old_write(rec, old, s)
    summ = write_run(RunResult(s, _Finished(rec), read_recording(rec).events), new)
    assert_same_results(new, old)
    with np.load(new / TRAJECTORY_FILE) as z:
        assert z["follow"].dtype == np.int8 and not z["follow"].any()
    for a in summ["agents"].values():
        assert a.get("state_s", {"none": 1.0}).keys() == {"none"}


def test_state_seconds_add_up_to_each_followers_time_alive(tmp_path):
    """summary.json's `state_s`: followers only, {state: seconds}, summing to the time the
    follower was alive (rows but the last, times dt), written the same from the recording and
    from memory."""
    s = load_scenario(ROOT / "scenarios" / "case2.toml")
    rec = tmp_path / RECORDING_FILE
    synthetic(rec, s, 300, quirks=False)
    summ = write_run(RunResult(s, _Finished(rec), read_recording(rec).events), tmp_path / "new")
    old_write(rec, tmp_path / "old", s)
    assert_same_results(tmp_path / "new", tmp_path / "old")
    with np.load(tmp_path / "new" / TRAJECTORY_FILE) as z:
        alive, ids, follow = z["alive"], z["ids"], z["follow"]
    names = {str(f) for f in FollowState}
    for k, aid in enumerate(ids.tolist()):
        a = summ["agents"][str(aid)]
        if a["role"] == "leader":
            assert "state_s" not in a
            continue
        assert set(a["state_s"]) <= names and all(v > 0 for v in a["state_s"].values())
        assert sum(a["state_s"].values()) == pytest.approx(alive[:-1, k].sum() * s.run.dt)
        seen = {str(FOLLOW_STATES[c]) for c in np.unique(follow[:-1, k][alive[:-1, k]])}
        assert set(a["state_s"]) == seen


class _Finished:
    """A recorder whose recording is written: write_run streams it."""

    def __init__(self, path: Path):
        self.path = path

    def finished(self) -> Path:
        return self.path

    def arrays(self):  # pragma: no cover - write_run must not call it
        raise AssertionError("write_run read the arrays into memory")


@pytest.mark.slow  # a whole run in-process
def test_a_real_run_with_faults_streams_the_same_results(tmp_path):
    """faults.toml's first 26 s (a kill, a restart) through the engine: the world's own
    summary (its events and figures) and the arrays, as the memory way writes them."""
    s = load_scenario(FAULTS)
    res = run_sim(s, 26.0, recording=tmp_path / RECORDING_FILE)
    new = tmp_path / "new"
    summ = write_run(res, new)
    assert summ["faults"] and summ["complete"] is True
    old = tmp_path / "old"
    old_write(tmp_path / RECORDING_FILE, old, res.scenario, res.events, res.extra, res.agent_extra)
    assert_same_results(new, old)
    assert json.loads((new / SUMMARY_FILE).read_text())["faults"][0]["kind"] == "kill"
    # run_sim keeps its ticks (write_run wrote from those): the recording streamed, the same files
    streamed = tmp_path / "streamed"
    streamed.mkdir()
    _write_streamed(tmp_path / RECORDING_FILE, streamed, res)
    assert_same_results(streamed, old)


def import_reader() -> None:
    import mcap.records  # noqa: F401
    import mcap.stream_reader  # noqa: F401


def peak_bytes(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_memory_does_not_grow_with_the_run_length(tmp_path, monkeypatch):
    """tracemalloc's peak while the results of a recording of T and of 4T ticks are written:
    about the same when streamed, about 4 times when every row is read into memory."""
    monkeypatch.setattr(results_stream, "CHUNK", 256)  # the chunks and the copy's blocks smaller than
    monkeypatch.setattr(results_stream, "COPY_BLOCK", 64 * 1024)  # the shorter run's arrays
    s = faults_scenario(0.01)  # faults at 20 s and later: windows in the longer run only
    peaks: dict[tuple[str, int], int] = {}
    import_reader()  # imported before, not counted in the first peak
    for ticks in (1500, 6000):
        d = tmp_path / str(ticks)
        d.mkdir()
        rec = d / RECORDING_FILE
        # MCAP chunks of 250 ticks, as a world makes them; the events (summary.json lists them) as many
        synthetic(rec, s, ticks, seed=2, quirks=False, flush_every=250, switch_every=ticks // 20)
        events = read_recording(rec).events
        res = RunResult(s, _Finished(rec), events, {})
        peaks["streamed", ticks] = peak_bytes(partial(write_run, res, d / "new"))
        peaks["memory", ticks] = peak_bytes(partial(old_write, rec, d / "old", s, events))
        assert_same_results(d / "new", d / "old")
    small, big = peaks["streamed", 1500], peaks["streamed", 6000]
    assert big < 1.1 * small, peaks
    assert peaks["memory", 6000] > 3 * peaks["memory", 1500], peaks  # the test sees growth where there is some
    assert big * 4 < peaks["memory", 6000], peaks


def test_force_removes_a_temporary_directory_left_behind(tmp_path):
    """A world killed while it wrote its results leaves its `.results-*` directory; `--force`
    clears it with the old results."""
    from swarm.offline.results import claim_out_dir

    (tmp_path / RECORDING_FILE).write_bytes(b"")
    left = tmp_path / (results_stream.RESULTS_TMP + "abc")
    left.mkdir()
    (left / "x.npy").write_bytes(b"0" * 10)
    claim_out_dir(tmp_path, force=True)
    assert not left.exists() and not (tmp_path / RECORDING_FILE).exists()


def test_keep_max_keeps_a_small_run_and_streams_a_larger_one(tmp_path):
    """`StreamRecorder(keep=True, keep_max=M)` (the world process): the ticks kept in memory
    while (ticks + 1) x agents <= M, agents added at run time included; past it nothing is
    kept and the results are streamed from the recording."""
    s = load_scenario(ROOT / "scenarios" / "case2.toml")
    ticks, n = 20, len(s.agents)
    cells = (ticks + 1) * n
    for keep_max, kept in ((None, True), (cells, True), (cells - 1, False)):
        r = StreamRecorder(s, ticks, tmp_path / f"{keep_max}.mcap", keep=True, keep_max=keep_max)
        assert (r.memory is not None) is kept, keep_max
        r.close()
    r = StreamRecorder(s, ticks, tmp_path / "added.mcap", keep=True, keep_max=cells + ticks + 1)
    spec = {"role": "follower", "x": 1.0, "y": 2.0, "heading": 0.0, "speed": 12.0}
    more = s.model_copy(update={"agents": [*s.agents, AgentSpec(id=98, **spec)]})
    r.add_agent(more)  # n + 1 columns: still kept
    assert r.memory is not None and r.memory.x.shape == (ticks + 1, n + 1)
    r.add_agent(more.model_copy(update={"agents": [*more.agents, AgentSpec(id=99, **spec)]}))
    assert r.memory is None and r.kept() is None  # too large now: streamed from the recording
