"""swarm.study (swarm/study/api.py, plan.py, sweeps.py): the Python API of `swarm study`, in this
process (workers=1): the CLI's rows and files, an executor of one's own, the grid's checks, the
time per selection state."""

from __future__ import annotations

import csv
import math
import re
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import swarm
from swarm.cli.main import app
from swarm.contracts.errors import UsageError
from swarm.contracts.scenario import load_scenario
from swarm.study.scenario import Jitter, Setting, Template, varied
from swarm.study.swarms import STATE_COLUMNS, state_outcome, state_totals
from swarm.study.sweeps import grid_axes, tuning_fields

ROOT = Path(__file__).resolve().parents[2]
SMALL = dict(n=4, leaders=1, sensing_range=[math.inf, 40.0], seeds=2, duration=6.0, dt=0.1)


def read(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def without_wall(rows: list[dict]) -> list[dict]:
    return sorted(
        ({k: "" if v is None else str(v) for k, v in r.items() if k != "wall_s"} for r in rows),
        key=lambda r: str(sorted(r.items())),
    )


def test_swarm_study_is_reached_from_import_swarm():
    assert "study" in dir(swarm)
    assert swarm.study.run_scenario is swarm.study.api.run_scenario


@pytest.mark.slow
def test_run_swarms_writes_the_clis_files_and_rows(tmp_path, capsys):
    r = swarm.study.run_swarms(**SMALL, workers=1, out=tmp_path / "api", plot=False)
    assert "study swarms: 4/4 runs" in capsys.readouterr().err  # no terminal: a line, not a bar
    assert r.kind == "swarms" and not r.interrupted and r.engine == "batch"
    assert len(r.rows) == 4 and len(r.summary) == 2
    assert without_wall(read(r.runs_csv)) == without_wall(r.rows)
    res = CliRunner().invoke(
        app,
        ["study", "swarms", "--n", "4", "--leaders", "1", "--range", "inf,40", "--seeds", "2", "--duration", "6"]
        + ["--dt", "0.1", "-j", "1", "--no-plot", "-q", "--out", str(tmp_path / "cli")],
    )
    assert res.exit_code == 0, res.output
    assert "rows -> " in res.output and "study swarms: 4/4" not in res.output  # -q: no progress
    assert without_wall(read(tmp_path / "cli" / "runs.csv")) == without_wall(read(r.runs_csv))
    assert read(tmp_path / "cli" / "summary.csv") == read(r.summary_csv)


@pytest.mark.slow
def test_an_executor_of_ones_own_runs_the_same_jobs(tmp_path):
    seen = []

    def serial(worker, jobs, on_row):
        for job in jobs:
            seen.append(job)
            rows = worker(job)
            for row in rows if isinstance(rows, list) else [rows]:
                on_row(row)

    plan = swarm.study.plan_swarms(**SMALL, workers=1)
    mine = swarm.study.execute(plan, tmp_path / "mine", serial, progress=False)
    local = swarm.study.execute(plan, tmp_path / "local", swarm.study.local_executor(1), progress=False)
    assert seen == plan.jobs and len(mine.rows) == plan.runs == 4
    assert without_wall(mine.rows) == without_wall(local.rows)


@pytest.mark.slow
def test_run_scenario_sweeps_a_law_parameter_and_names_its_column(tmp_path):
    r = swarm.study.run_scenario(
        ROOT / "scenarios" / "case2.toml",
        grid={"range": [math.inf], "c1": [1.0, 2.0]},
        seeds=1,
        duration=2.0,
        workers=1,
        out=tmp_path / "s",
        plot=False,
        progress=False,
    )
    header = next(csv.reader(r.runs_csv.open()))
    assert header[:4] == ["setting", "c1", "range", "seed"]  # the axes in their order, whatever the grid's
    assert sorted(row["setting"] for row in r.rows) == ["c1=1 range=inf", "c1=2 range=inf"]


@pytest.mark.parametrize(
    "grid, message",
    [
        ({"c3": [1]}, "'c3' is not an axis of a scenario study"),
        ({"noise": [-1]}, "grid['noise']: -1 is out of range"),
        ({"safety": [0.5]}, "0 (off, measuring only) or 1 (on)"),
        ({"param.1k": [1]}, "'1k' is not a parameter name"),
        ({"c1": [0]}, "must be a positive finite number"),
    ],
)
def test_a_bad_grid_is_refused_naming_the_key(grid, message):
    with pytest.raises(UsageError, match=None) as e:
        grid_axes(grid)
    assert message in str(e.value)


def test_a_tuning_name_that_is_no_field_names_the_valid_fields():
    fields = tuning_fields()
    assert {"hold_s", "coast_s", "reach", "edge", "search_pitch"} <= set(fields)
    with pytest.raises(UsageError) as e:
        grid_axes({"tuning.nope": [1.0]}, {"tuning.nope": "--param tuning.nope"})
    assert "--param tuning.nope: 'nope' is not a field of the selection tuning" in str(e.value)
    assert all(f in str(e.value) for f in fields)


def test_a_tuning_axis_sets_the_scenarios_sensing_tuning_and_nothing_else():
    path = ROOT / "scenarios" / "case2-range.toml"
    spec = load_scenario(path)
    template = Template(spec.model_dump(), str(path), (str(path.parent),))
    got = varied(template, Setting((("tuning.coast_s", 2.0), ("tuning.reach", 0.7))), Jitter(), 0)
    assert got.sensing.tuning.coast_s == 2.0 and got.sensing.tuning.reach == 0.7
    assert got.sensing.tuning.hold_s == spec.sensing.tuning.hold_s and got.sensing.range == spec.sensing.range
    assert Setting((("tuning.coast_s", 2.0),)).label() == "tuning.coast_s=2"


def test_the_cli_refuses_a_tuning_name_that_is_no_field(tmp_path):
    res = CliRunner().invoke(
        app,
        [
            "study",
            "scenario",
            str(ROOT / "scenarios" / "case2.toml"),
            "--param",
            "tuning.nope=1,2",
            "--out",
            str(tmp_path / "x"),
        ],
    )
    assert res.exit_code == 2, res.output
    assert "--param tuning.nope" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "x").exists()


def test_time_per_state_is_the_mean_over_followers_and_nan_without_it():
    summary = {
        "agents": {
            "1": {"role": "leader"},
            "2": {"role": "follower", "state_s": {"keep": 8.0, "coast": 2.0}},
            "3": {"role": "follower", "state_s": {"keep": 4.0, "search": 6.0}},
        }
    }
    got = state_outcome(summary)
    assert got["state_s_keep"] == 6.0 and got["state_s_coast"] == 1.0 and got["state_s_search"] == 3.0
    assert got["state_s_hold"] == 0.0 and set(got) == set(STATE_COLUMNS)
    absent = state_outcome({"agents": {"2": {"role": "follower"}}})
    assert all(math.isnan(v) for v in absent.values())
    rows = [got, absent, {k: "" for k in STATE_COLUMNS}]  # a run with the figures, one without, a CSV gap
    assert state_totals(rows)["state_s_keep"] == 6.0
    assert state_totals([absent]) == {}


@pytest.mark.slow
def test_the_python_api_pages_study_example_runs(tmp_path, monkeypatch, capsys):
    """docs/reference/api.md#study's block, as written (its output folder moved to tmp_path)."""
    text = (ROOT / "docs" / "reference" / "api.md").read_text()
    block = re.search(r"```python\n(.*?)```", text[text.index("## Studies {#study}") :], re.S)
    assert block, "no python block in the Studies section"
    monkeypatch.chdir(ROOT)
    exec(compile(block[1].replace('"runs/', f'"{tmp_path}/'), "api.md#study", "exec"), {})
    out = capsys.readouterr().out
    assert "c1=1 range=inf 2 " in out and "4 rows" in out
    assert (tmp_path / "study-example" / "summary.csv").exists()


@pytest.mark.parametrize(
    "flag, level, shown",
    [(False, "", True), (True, "", False), (False, "WARNING", False), (False, "info", True), (False, "40", False)],
)
def test_progress_is_off_with_q_here_or_swarm_q(monkeypatch, flag, level, shown):
    from swarm.cli.study import _progress

    monkeypatch.setenv("SWARM_LOG_LEVEL", level)
    assert _progress(flag) is shown


# -- rows keyed by (setting, seed): resume, no duplicate; the workers' cap ------------------------


class Counting:
    """A serial executor that counts the runs it runs and stops (Ctrl-C) after `stop_after` rows."""

    def __init__(self, stop_after: int | None = None, twice: bool = False):
        self.ran, self.stop_after, self.twice = 0, stop_after, twice

    def __call__(self, worker, jobs, on_row):
        for job in jobs:
            rows = worker(job)
            for row in rows if isinstance(rows, list) else [rows]:
                if self.stop_after is not None and self.ran == self.stop_after:
                    raise KeyboardInterrupt
                self.ran += 1
                on_row(row)
                if self.twice:  # a task run again after its worker died: its rows come back twice
                    on_row(dict(row))


@pytest.mark.slow
def test_resume_runs_only_the_runs_not_finished_and_each_row_is_written_once(tmp_path):
    opts = dict(SMALL, seeds=5, batch=False)  # 2 settings x 5 seeds, one run per job
    first = Counting(stop_after=3)
    cut = swarm.study.run_swarms(**opts, out=tmp_path / "s", executor=first, plot=False, progress=False)
    assert cut.interrupted and len(read(cut.runs_csv)) == 3 and first.ran == 3
    lines = []
    second = Counting()
    done = swarm.study.run_swarms(
        **opts, resume=tmp_path / "s", executor=second, plot=False, progress=False, say=lines.append
    )
    assert second.ran == 10 - 3  # the three finished runs were not run again
    assert done.resumed == 3 and not done.interrupted and done.duplicates == 0
    assert "resume: 3 of 10 runs already in" in "\n".join(lines) and "7 to run" in "\n".join(lines)
    rows = read(done.runs_csv)
    assert sorted((r["range"], r["seed"]) for r in rows) == sorted(
        (g, str(s)) for g in ("inf", "40.0") for s in range(5)
    )
    assert rows[:3] == read(cut.runs_csv)[:3]
    assert [int(line["runs"]) for line in read(done.summary_csv)] == [5, 5]
    third = Counting()
    again = swarm.study.run_swarms(**opts, resume=tmp_path / "s", executor=third, plot=False, progress=False)
    assert third.ran == 0 and len(read(again.runs_csv)) == 10  # nothing left to run


@pytest.mark.slow
def test_a_row_that_comes_back_twice_is_written_once(tmp_path):
    r = swarm.study.run_swarms(**SMALL, out=tmp_path / "s", executor=Counting(twice=True), plot=False, progress=False)
    assert r.duplicates == 4 and len(read(r.runs_csv)) == 4 and len(r.rows) == 4


@pytest.mark.slow
def test_resume_drops_a_line_cut_short_and_refuses_another_studys_csv(tmp_path):
    swarm.study.run_swarms(**SMALL, out=tmp_path / "s", workers=1, plot=False, progress=False)
    csv_path = tmp_path / "s" / "runs.csv"
    text = csv_path.read_text()
    csv_path.write_text(text[: text.rindex("\n", 0, len(text) - 1) + 12])  # the last row cut short by a kill
    runner = Counting()
    r = swarm.study.run_swarms(**SMALL, resume=tmp_path / "s", executor=runner, plot=False, progress=False)
    assert runner.ran == 1 and r.resumed == 3 and len(read(csv_path)) == 4
    with pytest.raises(UsageError, match="columns of another study"):
        swarm.study.run_gains(c1=[1], c2=[0.5], ratios=[1], starts=1, duration=2, resume=tmp_path / "s", workers=1)
    with pytest.raises(UsageError, match="nothing to resume"):
        swarm.study.run_swarms(**SMALL, resume=tmp_path / "nothing", workers=1)


def test_a_run_timeout_needs_an_executor_that_can_end_a_run(tmp_path):
    with pytest.raises(UsageError, match="run_timeout: this executor cannot end a run"):
        swarm.study.run_swarms(**SMALL, out=tmp_path / "s", executor=Counting(), run_timeout=5)
    with pytest.raises(UsageError, match="run_timeout: -1 must be a positive number"):
        swarm.study.run_swarms(**SMALL, out=tmp_path / "s", workers=1, run_timeout=-1)


@pytest.mark.parametrize(
    "asked, capacity, jobs, got, line",
    [
        (1000, 2, 2, 2, "--workers 1000 capped at 2: this machine has 2 cores"),
        (1000, 8, 3, 3, "--workers 1000 capped at 3: the study has 3 jobs"),
        (0, 2, 40, 2, None),  # 0: all there are, nothing to say
        (2, 2, 40, 2, None),
        (3, 4, 1, 1, "--workers 3 capped at 1: the study has 1 job"),
    ],
)
def test_workers_are_capped_at_the_machine_and_the_jobs_with_one_line(asked, capacity, jobs, got, line):
    from swarm.study.plan import capped

    assert capped(asked, capacity, "this machine has 2 cores", jobs, "--workers") == (got, line)


def test_a_key_cell_is_the_same_from_a_fresh_row_and_from_its_csv_text():
    from swarm.study.plan import cell, typed

    for fresh, text in [(10, "10"), (40.0, "40.0"), (40, "40.0"), (math.inf, "inf"), (True, "True"), (None, "")]:
        assert cell(fresh) == cell(text) == cell(typed(text))
    assert cell("sticky") == "sticky" and typed("1;0;2") == "1;0;2" and typed("3") == 3


def test_a_scheduler_address_is_checked_and_the_missing_extra_named(monkeypatch, tmp_path):
    from swarm.study.cluster import dask_executor

    with pytest.raises(UsageError, match="'nonsense' is not a scheduler's address: give tcp://HOST:PORT"):
        dask_executor("nonsense")
    res = CliRunner().invoke(
        app, ["study", "swarms", "--seeds", "2", "--scheduler", "10.0.0.1", "--out", str(tmp_path / "x")]
    )
    assert res.exit_code == 2 and "--scheduler: '10.0.0.1' is not a scheduler's address" in res.output
    assert not (tmp_path / "x").exists()
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(UsageError, match=r"pip install 'swarm-circumnav\[cluster\]'"):
        dask_executor("tcp://10.0.0.1:8786")
