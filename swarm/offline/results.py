"""A run's output directory: never overwritten by accident, and rebuilt after a crash.

- `claim_out_dir(out, force)`: refuses a directory that already holds results (unless
  `force`, which removes them and the old logs first, so a new run never mixes with an
  old one).
- `needs_export(run_dir)`: a recording without the files made from it (a world that died
  before writing them); `recover(run_dir)` rebuilds them (`swarm.world.recording.recover_run`)
  and says what it rebuilt (a `Recovery`, whose `line()` `swarm plot / export / up` print).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts.vocabulary import Coded, ExitCode
from swarm.world.files import RECORDING_FILE, RESULT_FILES, RESULTS_TMP, SUMMARY_FILE, TRAJECTORY_FILE

PLOT_NAMES = (
    "trajectories.png",
    "distance.png",
    "control.png",
    "graph.png",
    "overview.png",
    "neighbours.png",
    "states.png",
)
PLOT_SUFFIXES = (".png", ".pdf", ".svg")  # `swarm plot --format`
# `swarm plot --animate`, the Foxglove layout of `swarm plot` / `swarm up --foxglove`; `swarm export --csv`
# writes csv/agent-<id>.csv
DERIVED_NAMES = ("animation.gif", "foxglove-layout.json")


def derived_files(out: Path) -> list[Path]:
    """The files made from a run's results that `out` holds: figures in every format,
    the animation, the per-agent CSVs."""
    names = [Path(n).with_suffix(s).name for n in PLOT_NAMES for s in PLOT_SUFFIXES] + list(DERIVED_NAMES)
    return [out / n for n in names if (out / n).exists()] + sorted((out / "csv").glob("agent-*.csv"))


class OutDirError(Coded):
    """The output directory cannot be used; the message is one line naming it."""

    exit_code = ExitCode.USAGE


def results_in(out: Path) -> list[str]:
    """Names of the result files `out` holds (recording, trajectory, summary)."""
    return [name for name in RESULT_FILES if (out / name).exists()]


def claim_out_dir(out: Path, force: bool) -> None:
    """Make `out` ready for a new run's results, or raise OutDirError."""
    if out.exists() and not out.is_dir():
        raise OutDirError(f"--out {out} is a file, not a directory")
    held = results_in(out) if out.is_dir() else []
    if held and not force:
        raise OutDirError(
            f"--out {out} already holds the results of a run ({', '.join(held)}); "
            "choose another directory, or pass --force to replace them"
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name in held:
            (out / name).unlink(missing_ok=True)
        for path in derived_files(out):  # never an old run's figures next to a new run's data
            path.unlink(missing_ok=True)
        for tmp in out.glob(RESULTS_TMP + "*"):  # left by a world killed while it wrote its results
            shutil.rmtree(tmp, ignore_errors=True)
        if force:  # a crash's cause is read from the log's last line: never the old run's
            for log in (out / "logs").glob("*.log"):
                log.unlink()
    except OSError as e:
        raise OutDirError(f"--out {out}: {e.strerror or e}") from None


def needs_export(run_dir: Path) -> bool:
    """A recording without the files made from it (the world died before its end)."""
    return (run_dir / RECORDING_FILE).is_file() and not (
        (run_dir / TRAJECTORY_FILE).is_file() and (run_dir / SUMMARY_FILE).is_file()
    )


@dataclass(frozen=True)
class Recovery:
    """What `recover` rebuilt from a run's recording: ticks 0..`ticks` (t = 0 to
    `sim_time` s), from a recording the world `finished` or one cut short."""

    run_dir: Path
    ticks: int
    sim_time: float
    finished: bool

    def line(self) -> str:
        """The line `swarm plot / export / up` print about it."""
        return (
            f"recovered {self.ticks + 1} ticks (t = 0 to {self.sim_time:.2f} s) from the recording "
            f"({'finished' if self.finished else 'cut short'}) into {self.run_dir}: trajectory.npz, "
            "summary.json (complete: false)"
        )


def recover(run_dir: Path) -> Recovery | None:
    """Rebuild trajectory.npz and summary.json from the run's recording when they are missing
    (None: nothing to do). Raises ValueError (no readable recording) or
    swarm.world.stream.RecordingError (the files cannot be written)."""
    if not needs_export(run_dir):
        return None
    from swarm.world.recording import recover_run  # lazy: numpy, only to rebuild (the launcher imports none)

    summary = recover_run(run_dir)
    return Recovery(run_dir, int(summary["ticks"]), float(summary["sim_time"]), bool(summary.get("recording_finished")))
