"""The names of a run directory's result files and the error of writing them, in a module
without numpy: the `swarm up` launcher claims and checks its output directory with them
(swarm/offline/results.py, swarm/api/launch.py) and imports no numpy. world/stream.py,
world/recording.py and world/results_stream.py, which write the files, re-export them."""

from swarm.contracts.vocabulary import Coded, ExitCode

RECORDING_FILE = "recording.mcap"
TRAJECTORY_FILE = "trajectory.npz"
SUMMARY_FILE = "summary.json"
RESULT_FILES = (RECORDING_FILE, TRAJECTORY_FILE, SUMMARY_FILE)
RESULTS_TMP = ".results-"  # the temporary directory's prefix (swarm/offline/results.py removes one left behind)


class RecordingError(Coded):
    """The recording cannot be written (disk full, file too large, I/O error)."""

    exit_code = ExitCode.NO_SPACE
