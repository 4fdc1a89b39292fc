"""A run's results written from its recording by streaming, in memory that does not grow
with the run's length: O(agents x CHUNK), never O(agents x ticks).

`write_run` and `recover_run` (world/recording.py) write trajectory.npz and summary.json
from a recording.mcap this way: the same files as `recording_arrays(read_recording(path))`
then `np.savez_compressed` and `RunResult.summary` would (which kept a dict per tick, then
whole arrays: hundreds of MB after an hour), to the bit, in three passes:

1. `scan`: the recording read once for its header, the agents added at run time, its events,
   whether it was finished, and which ticks it holds (runs of consecutive ticks, a handful
   even in a recording with a tick written twice), hence the rows: ticks 0, 1, ... up to
   the first missing one. Nothing is kept per tick.
2. `fill`: read again, each tick message decoded in batches (consecutive ticks with the same
   agents: one `np.frombuffer` per batch) into each array's raw .npy file in a temporary
   directory beside the results, written at its tick's place, so that a tick written twice
   counts once, the later, as `recording_arrays` has it.
3. `Metrics` (world/results_metrics.py): summary.json's figures from those files read back CHUNK rows at a time, by
   streaming accumulators that do exactly the arithmetic of world/metrics.py, in the same
   order (switch counts, each agent's final radius, settling time, angular rate, the fault
   recoveries). Lookups of single rows (the final one, t at a tick) and `searchsorted` go
   through a memory map of the small `t` file: a few pages.

Then each .npy file is copied into trajectory.npz as the member `np.savez_compressed` writes
(same names, order, headers and deflate compression), and the temporary directory removed.
Memory: the chunk being decoded or read back, the expected radii of the graphs seen (at most
results_metrics.CACHE_MAX), pass 1's runs of consecutive ticks (one per gap or repeat) and the
events, which summary.json lists anyway. Disk: the temporary files hold the arrays uncompressed (41 N + 16
bytes per tick for N agents, about the recording's size) until trajectory.npz is written.
"""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.world.files import RESULTS_TMP as RESULTS_TMP
from swarm.world.stream import TICK_BYTES, TICK_ENCODING, RecordingError, read_recording, tick_width

CHUNK = 4096  # rows per chunk: memory is O(agents x CHUNK)
COPY_BLOCK = 1 << 20  # bytes per read when a .npy file is copied into the zip
PER_TICK = ("t", "missed", "x", "y", "heading", "u", "out", "alive", "follow")  # after the static arrays, in this order
AGENT_COLUMNS = ("x", "y", "heading", "u", "out", "alive", "follow")  # the per-tick arrays of one column per agent
_TIME_HEAD = 32  # bytes of a tick message's head (tick, time, n, missed)


@dataclass
class Scan:
    """What pass 1 found: the recording's header, events, whether it was finished, how many
    tick messages it holds and the rows (consecutive ticks from 0)."""

    scenario: Scenario
    ticks: int
    events: list[dict]
    complete: bool
    messages: int
    rows: int


class _Ticks:
    """Pass 1's tick counter: runs [lo, hi) of consecutive ticks, in the order they came."""

    def __init__(self) -> None:
        self.runs: list[list[int]] = []
        self.messages = 0

    def see(self, data: bytes) -> None:
        if len(data) < _TIME_HEAD:
            raise ValueError(f"a {TICK_ENCODING} message of {len(data)} bytes")
        n = int.from_bytes(data[16:24], "little", signed=True)
        tick_width(n, len(data))  # ValueError as decode_tick raises it
        k = int.from_bytes(data[0:8], "little", signed=True)
        self.messages += 1
        if self.runs and self.runs[-1][1] == k:
            self.runs[-1][1] = k + 1
        else:
            self.runs.append([k, k + 1])

    def rows(self) -> int:
        """Ticks 0, 1, ... present without a gap."""
        rows = 0
        for lo, hi in sorted(self.runs):
            if lo > rows:
                break
            rows = max(rows, hi)
        return rows


def scan(path: Path) -> Scan:
    """Pass 1 (see the module's docstring). ValueError as `read_recording` raises it."""
    ticks = _Ticks()
    rec = read_recording(path, on_tick=ticks.see)
    return Scan(rec.scenario, rec.ticks, rec.events, rec.complete, ticks.messages, ticks.rows())


# ------------------------------------------------------------------ pass 2: the arrays, to files


def _dtypes() -> dict[str, np.dtype]:
    f8, i8 = np.dtype(float), np.dtype(np.int64)
    return {
        "t": f8,
        "x": f8,
        "y": f8,
        "heading": f8,
        "u": f8,
        "out": i8,
        "alive": np.dtype(bool),
        "missed": i8,
        "follow": np.dtype(np.int8),
    }


FILL = {
    "t": np.nan,
    "x": np.nan,
    "y": np.nan,
    "heading": np.nan,
    "u": np.nan,
    "out": -1,
    "alive": False,
    "missed": 0,
    "follow": 0,
}


def _message_dtype(n: int, follow: bool = True) -> np.dtype:
    """A `swarm-tick-v2` message for n agents as one record (world/stream.py); follow False:
    a `swarm-tick-v1` one (no follow states)."""
    return np.dtype(
        [
            ("tick", "<i8"),
            ("time", "<f8"),
            ("n", "<i8"),
            ("missed", "<i8"),
            ("ids", "<i8", (n,)),
            ("x", "<f8", (n,)),
            ("y", "<f8", (n,)),
            ("heading", "<f8", (n,)),
            ("u", "<f8", (n,)),
            ("out", "<i8", (n,)),
            ("alive", "u1", (n,)),
        ]
        + ([("follow", "i1", (n,))] if follow else [])
    )


class NpyFiles:
    """The per-tick arrays of trajectory.npz as raw .npy files (header, then rows) in `dir`."""

    def __init__(self, dir: Path, rows: int, n: int):
        self.dir = dir
        self.rows, self.n = rows, n
        self.dtypes = _dtypes()
        self.shapes = {k: (rows,) if k in ("t", "missed") else (rows, n) for k in PER_TICK}
        self.header: dict[str, int] = {}
        self.files: dict[str, IO[bytes]] = {}
        for k in PER_TICK:
            f = open(self.path(k), "w+b")
            self.files[k] = f
            np.lib.format.write_array_header_1_0(
                f,
                {
                    "descr": np.lib.format.dtype_to_descr(self.dtypes[k]),
                    "fortran_order": False,
                    "shape": self.shapes[k],
                },
            )
            self.header[k] = f.tell()

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.npy"

    def width(self, key: str) -> int:
        return 1 if key in ("t", "missed") else self.n

    def write(self, key: str, row: int, block: np.ndarray) -> None:
        f = self.files[key]
        f.seek(self.header[key] + row * self.width(key) * self.dtypes[key].itemsize)
        f.write(np.ascontiguousarray(block, self.dtypes[key]).tobytes())

    def read(self, key: str, r0: int, r1: int) -> np.ndarray:
        """Rows r0..r1-1 of `key` (a copy)."""
        f = self.files[key]
        size = self.width(key) * self.dtypes[key].itemsize
        f.seek(self.header[key] + r0 * size)
        a = np.frombuffer(f.read((r1 - r0) * size), self.dtypes[key])
        return a if key in ("t", "missed") else a.reshape(r1 - r0, self.n)

    def flush(self) -> None:
        for f in self.files.values():
            f.flush()

    def close(self) -> None:
        for f in self.files.values():
            f.close()


class _Filler:
    """Pass 2: tick messages, in the file's order, to `NpyFiles` at their ticks' places.
    Consecutive messages of consecutive ticks with the same agent count are decoded and
    written as one batch; a tick that comes again starts a new batch written after the
    first one, so the later message is the one that stays."""

    def __init__(self, files: NpyFiles, ids: list[int], messages: int):
        self.files = files
        self.col = {aid: j for j, aid in enumerate(ids)}
        self.ids = np.array(ids, dtype=np.int64)
        self.left = messages  # the tick messages pass 1 counted: a file that grew since is read as it was
        self.batch: list[bytes] = []
        self.k0 = self.n = 0
        self.width = TICK_BYTES

    def add(self, data: bytes) -> None:
        if self.left <= 0:
            return
        self.left -= 1
        k = int.from_bytes(data[0:8], "little", signed=True)
        n = int.from_bytes(data[16:24], "little", signed=True)
        width = tick_width(n, len(data))
        if self.batch and (
            k != self.k0 + len(self.batch) or n != self.n or width != self.width or len(self.batch) >= CHUNK
        ):
            self.flush()
        if not self.batch:
            self.k0, self.n, self.width = k, n, width
        self.batch.append(data)

    def flush(self) -> None:
        if not self.batch:
            return
        follow = self.width == TICK_BYTES
        recs = np.frombuffer(b"".join(self.batch), _message_dtype(self.n, follow))
        k0, self.batch = self.k0, []
        lo, hi = max(k0, 0), min(k0 + len(recs), self.files.rows)  # ticks outside the rows are not kept
        if lo >= hi:
            return
        recs = recs[lo - k0 : hi - k0]
        f, m, n = self.files, len(recs), self.files.n
        f.write("t", lo, recs["time"])
        f.write("missed", lo, recs["missed"])
        ids = recs["ids"]
        keys = AGENT_COLUMNS if follow else AGENT_COLUMNS[:-1]  # v1: follow stays FILL (none)
        if self.n <= n and (ids == self.ids[: self.n]).all():  # the usual case: the scenario's order
            for key in AGENT_COLUMNS:
                block = np.full((m, n), FILL[key], dtype=f.dtypes[key])
                if key in keys:
                    block[:, : self.n] = recs[key]
                f.write(key, lo, block)
            return
        blocks = {key: np.full((m, n), FILL[key], dtype=f.dtypes[key]) for key in AGENT_COLUMNS}
        for r in range(m):
            cols = [self.col[int(i)] for i in ids[r]]
            for key in keys:
                blocks[key][r, cols] = recs[key][r]
        for key, block in blocks.items():
            f.write(key, lo, block)


def fill(path: Path, sc: Scan, files: NpyFiles) -> None:
    """Pass 2 (see the module's docstring)."""
    filler = _Filler(files, list(sc.scenario.ids), sc.messages)
    read_recording(path, on_tick=filler.add, events=False)
    filler.flush()
    files.flush()


# ------------------------------------------------------------------ the files read back, for pass 3


def _chunks(files: NpyFiles, keys: tuple[str, ...], start: int = 0) -> Iterator[Any]:
    for r0 in range(start, files.rows, CHUNK):
        r1 = min(r0 + CHUNK, files.rows)
        yield r0, r1, {k: files.read(k, r0, r1) for k in keys}


# ------------------------------------------------------------------ trajectory.npz from the files


def write_npz(dest: IO[bytes], static: dict[str, np.ndarray], files: NpyFiles) -> None:
    """trajectory.npz as `np.savez_compressed(dest, **static, **per_tick)` writes it: the
    per-tick members copied from their .npy files a block at a time."""
    with zipfile.ZipFile(dest, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as z:
        for key, val in static.items():
            with z.open(key + ".npy", "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, np.asanyarray(val), allow_pickle=True)
        for key in PER_TICK:
            with z.open(key + ".npy", "w", force_zip64=True) as fid, open(files.path(key), "rb") as src:
                shutil.copyfileobj(src, fid, COPY_BLOCK)


@contextmanager
def streamed(path: Path, work_in: Path, sc: Scan | None = None) -> Iterator[tuple[Scan, NpyFiles]]:
    """Passes 1 and 2: the recording at `path` scanned (unless `sc` is given) and its per-tick
    arrays written to .npy files in a temporary directory in `work_in`, removed on leaving.
    ValueError as `read_recording` raises it; RecordingError when the files cannot be written."""
    if sc is None:
        sc = scan(path)
    try:
        work = Path(tempfile.mkdtemp(prefix=RESULTS_TMP, dir=work_in))
    except OSError as e:
        raise RecordingError(f"cannot write {work_in}: {e.strerror or e}") from None
    try:
        try:
            files = NpyFiles(work, sc.rows, len(sc.scenario.ids))
        except OSError as e:
            raise RecordingError(f"cannot write {work}: {e.strerror or e}") from None
        try:
            try:
                fill(path, sc, files)
            except OSError as e:
                raise RecordingError(f"cannot write {work}: {e.strerror or e}") from None
            yield sc, files
        finally:
            files.close()
    finally:
        shutil.rmtree(work, ignore_errors=True)
