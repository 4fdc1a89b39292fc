"""`swarm study swarms|gains` (docs/design/studies.md): rows, tables, plots, bad options, and
Ctrl-C keeping every finished row with no worker left behind."""

from __future__ import annotations

import csv
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import psutil
import pytest
from click.testing import CliRunner
from deadlines import DEADLINE
from typer.main import get_command

from swarm.cli.main import app
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.offline.batch import refusal, run_batch
from swarm.offline.sim import run_sim
from swarm.runtime.procs import Group, wait_until
from swarm.study.batch import gain_chunks, run_gain_chunk
from swarm.study.figures import gains_figure
from swarm.study.gains import GainJob, run_gain
from swarm.study.scenario import Jitter, Setting, Template, varied
from swarm.study.swarms import SwarmSetting, cut_off_at_start, random_swarm, run_swarm, summarise_swarms

ROOT = Path(__file__).resolve().parents[2]


_COMMAND = get_command(app)  # built once (typer's CliRunner builds it on every call: ~0.1 s of CPU)


def invoke(*args):
    return CliRunner().invoke(_COMMAND, [str(a) for a in args])


def rows(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


@pytest.mark.slow  # a whole run in-process
def test_swarms_study_compares_rules_on_the_same_swarms(tmp_path):
    res = invoke(
        "study",
        "swarms",
        "--seeds",
        "2",
        "--n",
        "6",
        "--selection",
        "sticky,nearest",
        "--duration",
        "20",
        "-j",
        "1",
        "--out",
        tmp_path / "s",
    )
    assert res.exit_code == ExitCode.OK, res.output
    runs = rows(tmp_path / "s" / "runs.csv")
    assert len(runs) == 4
    assert {(r["selection"], r["seed"]) for r in runs} == {(a, b) for a in ("sticky", "nearest") for b in "01"}
    summary = rows(tmp_path / "s" / "summary.csv")
    assert {r["selection"] for r in summary} == {"sticky", "nearest"}
    assert all(int(r["runs"]) == 2 for r in summary)
    assert (tmp_path / "s" / "study.png").stat().st_size > 1000
    assert "N=6 L=2 sticky range unlimited" in res.stdout


@pytest.mark.slow  # a whole run in-process: the long tier
def test_on_a_known_swarm_sticky_settles_where_rooted_chatters_and_nearest_cycles():
    # seed 0 of the default setting (10 agents, 2 leaders, unlimited sensing), 60 s (was 120 s:
    # sticky settles at 46 s either way with 4 switches; rooted switches 96 times in 60 s, 189
    # in 120 s; nearest leaves 8 followers unrooted in both)

    base = dict(n=10, leaders=2, duration=60.0)
    sticky, rooted, nearest = (
        run_swarm((SwarmSetting(selection=r, **base), 0)) for r in ("sticky", "rooted", "nearest")
    )
    assert sticky["converged"] and sticky["unrooted"] == 0 and sticky["switches_max"] <= 2
    assert rooted["switches"] > 10 * max(1, sticky["switches"]) and not rooted["converged"]
    assert nearest["unrooted"] > 0 and not nearest["converged"]


def test_every_run_counts_and_cut_off_swarms_are_also_shown_apart():
    far = SwarmSetting(n=6, leaders=1, range=1.0)  # nobody senses anybody
    assert cut_off_at_start(random_swarm(far, 0))
    assert not cut_off_at_start(random_swarm(SwarmSetting(n=6, leaders=1), 0))
    fake = [
        {
            **SwarmSetting().__dict__,
            "seed": k,
            "converged": k != 1,
            "cut_off": k > 0,
            "settling_time": 10.0,
            "switches": 0,
            "switches_max": 0,
            "switch_counts": "0;1",
            "unrooted": 0,
            "searching_s": float(k),
            "searching_max_s": 2.0 * k,
            "losses": k,
            "loss_switches_max": k,
            "wall_s": 0.1,
        }
        for k in range(3)
    ]
    (line,) = summarise_swarms(fake)
    assert (line["runs"], line["cut_off"], line["cut_off_converged"], line["converged"]) == (3, 2, 1, 2)
    assert line["converged_fraction"] == 2 / 3  # over every run, cut off or not
    assert line["switches_median"] == 0.5
    assert (line["searching_median_s"], line["searching_max_s"]) == (1.0, 4.0)
    assert (line["losses"], line["loss_switches_max"]) == (3, 2)


@pytest.mark.slow  # a whole run in-process
def test_gain_map_finds_where_the_law_settles():
    # docs/design/studies.md#gains: C2 = omega/2 settles a follower twice as fast as its
    # leader; C2 = 3 omega makes it oscillate about its orbit for ever.
    good = run_gain(GainJob(1.0, 0.5, 2.0, 0, duration=200.0))
    bad = run_gain(GainJob(1.0, 3.0, 2.0, 0, duration=200.0))
    assert math.isfinite(good["settling_time"]) and good["settling_time"] < 150
    assert math.isnan(bad["settling_time"])


@pytest.mark.slow  # a whole run in-process
def test_gain_map_batches_give_the_per_agent_rows():
    jobs = [GainJob(1.0, c2, q, k, duration=40.0) for c2 in (0.5, 3.0) for q in (0.6, 2.0) for k in range(2)]
    chunks = gain_chunks(jobs, workers=1)
    assert [len(c) for c in chunks] == [2, 2, 2, 2]  # four chunks per worker
    batched = [row for c in chunks for row in run_gain_chunk(c)]
    nan_free = [
        {k: "nan" if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()}
        for r in batched + [run_gain(j) for j in jobs]
    ]
    assert nan_free[: len(jobs)] == nan_free[len(jobs) :]
    assert any(r["settling_time"] == "nan" for r in nan_free) and any(r["settling_time"] != "nan" for r in nan_free)


@pytest.mark.slow  # a whole run in-process
def test_gains_study_table_and_plot(tmp_path):
    res = invoke(
        "study",
        "gains",
        "--c1",
        "1",
        "--c2",
        "0.5,3",
        "--ratios",
        "2",
        "--starts",
        "1",
        "--duration",
        "150",
        "-j",
        "1",
        "--out",
        tmp_path / "g",
    )
    assert res.exit_code == ExitCode.OK, res.output
    summary = {(float(r["c2"])): r["worst_settling_s"] for r in rows(tmp_path / "g" / "summary.csv")}
    assert math.isfinite(float(summary[0.5])) and math.isnan(float(summary[3.0]))
    assert (tmp_path / "g" / "gains.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "args, message",
    [
        (["swarms", "--selection", "random"], "--selection: 'random'"),
        (["swarms", "--speeds", "40,15"], "--speeds"),
        (["swarms", "--range", "far"], "--range: 'far' is not a number"),
        (["swarms", "--n", "3", "--leaders", "3"], "--leaders"),
        (["gains", "--c2", "0,1"], "--c2: '0' must be a positive"),
    ],
)
def test_bad_options_name_the_option(tmp_path, args, message):
    res = invoke("study", *args, "--out", tmp_path / "x")
    assert res.exit_code == ExitCode.USAGE
    assert message in res.output
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["--batch", "--per-agent"])
def test_ctrl_c_keeps_finished_rows_and_leaves_no_worker(tmp_path, engine):
    out = tmp_path / "s"
    # 20 s runs (was 60 s: the CPU spent before the second row; 60 runs still outlast the Ctrl-C)
    args = ["swarms", "--seeds", "60", "--n", "6", "--duration", "20", "-j", "2", "--out", str(out), engine]
    output, workers = interrupt_study(args, out)
    assert "stopped:" in output and "Traceback" not in output
    finished = rows(out / "runs.csv")
    assert 2 <= len(finished) < 60
    assert all(r["converged"] in ("True", "False") for r in finished)  # whole rows only
    assert len(rows(out / "summary.csv")) == 1
    assert_workers_gone(workers)


def interrupt_study(args: list[str], out: Path) -> tuple[str, list]:
    """`swarm study ARGS` in its own process group, Ctrl-C'd (SIGINT to the group, as a
    terminal does) once its runs.csv holds two rows: its output and its worker processes; it
    must have exited 130."""
    group = Group(session=True)
    proc = group.start(
        [sys.executable, "-m", "swarm", "study", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        csv_path = out / "runs.csv"

        def two_rows() -> bool:
            assert proc.poll() is None, proc.stdout.read()
            return csv_path.exists() and len(rows(csv_path)) >= 2

        if not wait_until(two_rows, 120, interval=0.1):
            pytest.fail("no rows within 120 s")
        workers = psutil.Process(proc.pid).children(recursive=True)
        assert workers, "the study should run on worker processes"
        group.signal(signal.SIGINT)  # what a terminal's Ctrl-C does
        output, _ = proc.communicate(timeout=DEADLINE)
    finally:
        group.kill()
    assert proc.returncode == ExitCode.INTERRUPTED, output
    return output, workers


def assert_workers_gone(workers: list) -> None:
    psutil.wait_procs(workers, timeout=10)
    assert not [w for w in workers if w.is_running() and w.status() != psutil.STATUS_ZOMBIE]


# -- swarm study scenario: one's own scenario and law ------------------------------------------

SMALL = """
name = "small"
[run]
dt = 0.05
duration = 8.0
[gains]
c1 = 1.0
c2 = 0.5
{law}
[sensing]
selection = "sticky"
[[agents]]
id = 1
role = "leader"
x = 5.0
y = 0.0
heading = 1.57
speed = 5.0
orbit_radius = 5.0
[[agents]]
id = 2
role = "follower"
x = -8.0
y = 3.0
heading = 0.0
speed = 4.0
[[agents]]
id = 3
role = "follower"
x = 2.0
y = -9.0
heading = 2.0
speed = 6.0
"""

MYLAW = '''
import math

import numpy as np


def pursuit(obs):
    """law(obs): the bearing term with gain [law.params] k, the heading term with C1."""
    j = obs.out
    if j is None:
        return obs.c2
    return obs.c1 * math.sin(j.heading - obs.heading) + obs.params["k"] * math.sin(j.bearing - obs.heading)


def vbearing(g_i, g_j, lambda_ij, c1, c2):
    """A vectorised law: numpy, element by element, on floats or arrays."""
    return c1 * np.tanh(np.arctan2(np.sin(g_j - g_i), np.cos(g_j - g_i))) + c2 * np.sin(lambda_ij - g_i)


vbearing.vectorised = True
'''


def own_scenario(tmp_path: Path, law: str) -> Path:
    """A small scenario in a directory of its own, with mylaw.py next to it."""
    (tmp_path / "mylaw.py").write_text(MYLAW)
    p = tmp_path / "small.toml"
    p.write_text(SMALL.format(law=law))
    return p


OBS_LAW = '[law]\nfollower = "mylaw:pursuit"\n[law.params]\nk = 0.5\n'


def vector_scenario(tmp_path: Path) -> Path:
    p = own_scenario(tmp_path, "")
    p.write_text(p.read_text().replace("c2 = 0.5\n", 'c2 = 0.5\nlaw = "mylaw:vbearing"\n', 1))
    return p


@pytest.mark.slow  # 12 runs and two figures in-process (about 2 s): the long tier
def test_a_study_of_ones_own_scenario_and_law_streams_rows_and_counts_them(tmp_path):
    (tmp_path / "mine").mkdir()
    src = own_scenario(tmp_path / "mine", OBS_LAW)
    res = invoke(
        "study", "scenario", src, "--seeds", "3", "--positions", "10", "--headings", "uniform",
        "--speeds", "0.1", "--param", "k=0.3,0.6", "--noise", "0,0.05", "-j", "1", "--out", tmp_path / "o",
    )  # fmt: skip
    assert res.exit_code == ExitCode.OK, res.output
    assert "engine: per-agent" in res.stdout and "'mylaw:pursuit'" in res.stdout
    runs = rows(tmp_path / "o" / "runs.csv")
    assert len(runs) == 2 * 2 * 3
    assert {(r["param.k"], r["noise"], r["seed"]) for r in runs} == {
        (k, n, s) for k in ("0.3", "0.6") for n in ("0.0", "0.05") for s in "012"
    }
    summary = rows(tmp_path / "o" / "summary.csv")
    assert len(summary) == 4
    for line in summary:
        mine = [r for r in runs if r["setting"] == line["setting"]]
        assert int(line["runs"]) == len(mine) == 3
        assert int(line["converged"]) == sum(r["converged"] == "True" for r in mine)
    assert "k=0.6 noise=0.05" in res.stdout
    assert (tmp_path / "o" / "study.png").stat().st_size > 1000
    assert (tmp_path / "o" / "sweep.png").stat().st_size > 1000


def test_what_a_study_varies(tmp_path):

    spec = load_scenario(own_scenario(tmp_path, OBS_LAW))
    t = Template(spec.model_dump(), "small.toml", (str(tmp_path),), duration=5.0)
    base = {a.id: a for a in spec.agents}
    setting = Setting((("c2", 0.3), ("param.k", 2.0), ("range", math.inf), ("noise", 0.1)))
    draws = [varied(t, setting, Jitter(positions=10, headings=0.5, speeds=0.2), seed) for seed in range(20)]
    for s in draws:
        assert s.run.duration == 5.0 and s.gains.c2 == 0.3 and s.law.params["k"] == 2.0 and s.sensing.range is None
        (f,) = s.faults
        assert (f.kind, f.at, f.duration, f.std, f.agent) == ("noise", 0.0, 5.0, 0.1, None)
        for a in s.agents:
            b = base[a.id]
            assert abs(a.x - b.x) <= 10 and abs(a.y - b.y) <= 10
            assert abs(math.remainder(a.heading - b.heading, 2 * math.pi)) <= 0.5 + 1e-12
            assert 0.8 * b.speed <= a.speed <= 1.2 * b.speed
            if a.role == "leader":
                assert a.orbit_radius / a.speed == pytest.approx(b.orbit_radius / b.speed)
    assert len({round(s.agents[1].x, 9) for s in draws}) == 20  # every seed its own draw
    assert [s.run.seed for s in draws] == list(range(20))
    again = varied(t, Setting((("noise", 0.2),)), Jitter(positions=10), 3)
    assert again.agents == varied(t, Setting((("noise", 0.0),)), Jitter(positions=10), 3).agents  # same starts
    assert again.faults[0].std == 0.2 and not varied(t, Setting((("noise", 0.0),)), Jitter(), 3).faults


@pytest.mark.slow  # two studies in-process
def test_a_vectorised_law_goes_through_the_batch_engine_with_the_per_agent_rows(tmp_path):
    src = vector_scenario(tmp_path)
    common = ["--seeds", "4", "--positions", "5", "--headings", "0.5", "--c2", "0.3,0.5", "-j", "1", "--no-plot"]
    auto = invoke("study", "scenario", src, *common, "--out", tmp_path / "a")
    per = invoke("study", "scenario", src, *common, "--engine", "per-agent", "--out", tmp_path / "p")
    assert auto.exit_code == per.exit_code == ExitCode.OK, auto.output + per.output
    assert "engine: batch (follower law 'mylaw:vbearing' is vectorised)" in auto.stdout
    assert "engine: per-agent" in per.stdout

    def by_run(path):
        return sorted(({k: v for k, v in r.items() if k != "wall_s"} for r in rows(path)), key=str)

    a, p = by_run(tmp_path / "a" / "runs.csv"), by_run(tmp_path / "p" / "runs.csv")
    assert len(a) == 8 and a == p
    assert any(r["switches"] != "0" or r["converged"] == "True" for r in a)  # runs that did something


@pytest.mark.slow  # three runs in each engine (about 0.35 s): the long tier
def test_a_vectorised_law_in_the_batch_engine_flies_the_per_agent_trajectories(tmp_path):

    spec = load_scenario(vector_scenario(tmp_path))
    t = Template(spec.model_dump(), "small.toml", (str(tmp_path),))
    runs = [varied(t, Setting(), Jitter(positions=8, headings=math.inf), seed) for seed in range(3)]
    assert refusal(runs[0]) is None  # the batch engine takes the vectorised law itself
    batched = run_batch(runs, lean=True)
    for s, b in zip(runs, batched):
        ref = run_sim(s).recorder.arrays()
        got = b.recorder.arrays()
        assert np.abs(got["x"] - ref["x"]).max() < 1e-9 and np.abs(got["y"] - ref["y"]).max() < 1e-9
        assert (got["out"] == ref["out"]).all()
        assert b.scenario.gains.law == "mylaw:vbearing"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--param", "k0.1"], "--param: 'k0.1'"),
        (["--noise", "-1"], "--noise: -1 is out of range"),
        (["--loss", "2"], "--loss: 2 is out of range"),
        (["--headings", "wide"], "--headings: 'wide' is not a number"),
        (["--engine", "batch"], "--engine batch: the batch engine does not run this study: its follower law"),
    ],
)
def test_bad_scenario_study_options_name_the_option(tmp_path, args, message):
    res = invoke("study", "scenario", own_scenario(tmp_path, OBS_LAW), *args, "--out", tmp_path / "x")
    assert res.exit_code == ExitCode.USAGE, res.output
    assert message in res.output
    assert not (tmp_path / "x").exists()


@pytest.mark.slow  # worker processes, stopped by a signal
def test_ctrl_c_keeps_a_scenario_studys_finished_rows(tmp_path):
    src = own_scenario(tmp_path, OBS_LAW)
    out = tmp_path / "o"
    args = ["--seeds", "200", "--positions", "5", "--duration", "30", "--workers", "2", "--out", str(out)]
    output, workers = interrupt_study(["scenario", str(src), *args], out)
    assert "engine: per-agent" in output and "stopped:" in output and "Traceback" not in output
    finished = rows(out / "runs.csv")
    assert 2 <= len(finished) < 200
    assert all(r["converged"] in ("True", "False") for r in finished)  # whole rows only
    (line,) = rows(out / "summary.csv")
    assert int(line["runs"]) == len(finished)
    assert_workers_gone(workers)


@pytest.mark.slow  # a figure drawn (about 0.6 s): the long tier
def test_a_small_gain_maps_title_and_colour_bar_label_fit_in_the_figure():
    # swarm study gains --c1 0.5,1,2 --c2 0.25,0.5 --ratios 0.5,1.5 --starts 2 cut both off (issue 25)
    summary = [
        {"c1": a, "c2": b, "ratio": q, "starts": 2, "worst_settling_s": 100.0}
        for a in (0.5, 1.0, 2.0)
        for b in (0.25, 0.5)
        for q in (0.5, 1.5)
    ]
    fig = gains_figure(summary, 300.0)
    fig.canvas.draw()
    box = fig.bbox
    label = fig.axes[-1].yaxis.label  # the colour bar's
    assert label.get_text().startswith("worst time into")
    for text in (fig.get_suptitle() and fig._suptitle, label):
        e = text.get_window_extent()
        assert box.x0 <= e.x0 and e.x1 <= box.x1 and box.y0 <= e.y0 and e.y1 <= box.y1, (text.get_text(), e, box)
