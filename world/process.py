"""The world process: hub of a run, ground truth, physics, sensors, the recording.

It opens the run's zenoh endpoint (router mode, so a local run needs no router
binary), answers join queries, watches the agents' liveliness tokens, and each tick
sends every live agent its own sensor frame, collects commands, steps `WorldCore`
and records the tick. At the end (or on SIGTERM/SIGINT) it writes trajectory.npz
and summary.json into its output directory, announces the end and closes.

All zenoh callbacks only put typed messages (world/inbox_messages.py) on one queue
(world/fairness.py);
everything else happens on the main thread. `World` is composed of parts, each with
what it depends on in its constructor: the run's shared state (world/state.py), the
inbox (world/inbox.py: what each message does), the joins (world/joins.py: join
queries) and the clock (world/clock.py: how ticks are paced); this module keeps the
zenoh keys, publishing and the results. world/main.py runs it from start to end.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable
from typing import Any, cast

import numpy as np

from swarm.contracts import wire
from swarm.contracts.transport import open_hub, query_statuses
from swarm.contracts.vocabulary import EventKind
from swarm.world.clock import Clock
from swarm.world.engine import Engine
from swarm.world.fairness import FairQueue
from swarm.world.inbox import Inbox
from swarm.world.inbox_messages import Admin, Info, Join, Supervise
from swarm.world.joins import Joins
from swarm.world.recording import RECORDING_FILE, DeferredRecorder, RecordingError, write_run
from swarm.world.roster import agent_figures
from swarm.world.state import RunState, WorldConfig

log = logging.getLogger(__name__)

__all__ = ["TRUTH_PERIOD", "World", "WorldConfig"]

TRUTH_PERIOD = 0.02  # s of wall time between ground-truth messages (observers, not the recording)
END_WAIT_S = 1.0  # s the world waits, after its end notice, for its agents' tokens to go (see `_close`)
# A run of at most this many agent-ticks ((ticks + 1) x agents, agents added at run time
# included) also keeps its ticks in memory (about 42 bytes each: 11 MB at most), and its
# results are written from them, without reading recording.mcap back (world/recording.py
# `write_run`: the same files to the bit); a larger one streams them from the recording.
KEEP_MAX_AGENT_TICKS = 1 << 18


class World:
    """The world process of one run: `state` (shared by the parts), `queue` (filled by the
    zenoh callbacks), `joins`, `inbox`, `clock`; the zenoh keys and what goes out on them."""

    def __init__(self, cfg: WorldConfig):
        self.cfg = cfg
        s = cfg.scenario
        self.ticks = int(round((cfg.duration or s.run.duration) / s.run.dt))
        # The tick itself (faults, frames, commands, events, record, step) is the engine's,
        # the same one `swarm sim` drives; this class is its zenoh shell.
        recording = None
        if cfg.out_dir is not None:
            try:
                cfg.out_dir.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise RecordingError(f"cannot create {cfg.out_dir}: {e.strerror or e}") from None
            recording = cfg.out_dir / RECORDING_FILE
        if cfg.plant is not None and cfg.clock != "realtime":
            raise ValueError(f"a world with a plant (robots) runs the realtime clock only, not {cfg.clock}")
        self.engine = Engine(
            s,
            self.ticks,
            joined=False,
            wall_clock=time.time,
            on_event=self._announce,
            recording=recording,
            plant=cfg.plant,
            keep=True,  # up to KEEP_MAX_AGENT_TICKS: the results without reading the recording back
            keep_max=KEEP_MAX_AGENT_TICKS,
        )
        self.rec = DeferredRecorder(self.engine.rec)  # written while the agents think (publish_frames)
        self.engine.rec = self.rec
        self.core = self.engine.core
        self.state = RunState(cfg, self.engine, self.ticks)
        self.book = self.state.book
        self.queue = FairQueue(self.state)
        self.joins = Joins(self.state, self.add_sense)
        self.inbox = Inbox(self.state, self.queue, self.joins)
        self.clock = Clock(self.state, self.inbox, self, cfg.deadline or s.run.lockstep_deadline)
        self.stopped_by: int | None = None  # the signal that stopped the run (-1: an error)
        self.truth_sent = 0.0
        self.truth_seq = 0  # the last truth message's sequence number (wire.next_seq): a tap counts gaps
        self.event_seq = 0  # the same for events
        self.frames_sent: dict[int, bytes] = {}  # this tick's encoded frames, by agent
        self.session: Any = None  # the zenoh session (`_open`)

    def run(self) -> int:
        """The run from the first join to the last tick (world/clock.py); its exit code."""
        return self.clock.run()

    def info(self, sensing: bool = False) -> dict[str, Any]:
        """The world's view of the run (world/inbox.py)."""
        return self.inbox.info(sensing)

    # -- zenoh plumbing (callbacks: enqueue only) -----------------------------------------
    def _open(self, session: Any = None) -> None:
        """Declare the world's keys on `session` (default: a new hub on cfg.listen; tests
        pass a fake one, tests/support/fakes.py); a failure closes the session again."""
        self.session = session if session is not None else open_hub(self.cfg.listen, self.cfg.auth)
        try:
            self._declare(self.session)
        except BaseException:  # an open session left behind would hang the exit
            self.session.close()
            raise

    def _declare(self, ses: Any) -> None:
        run = self.cfg.run
        fq = self.queue
        command, token, put = fq.command, fq.token, fq.enqueue
        self._subs = [
            ses.declare_subscriber(
                wire.agent_key(run, "*", "cmd"), lambda s: command(str(s.key_expr), s.payload.to_bytes())
            ),
            ses.liveliness().declare_subscriber(
                wire.agent_key(run, "*", "alive"), lambda s: token(str(s.key_expr), s.kind), history=True
            ),
            ses.declare_queryable(wire.agent_key(run, "*", "join"), lambda q: put(Join(q))),
            ses.declare_queryable(wire.world_info_key(run), lambda q: put(Info(q))),
            ses.declare_queryable(wire.world_admin_key(run), lambda q: put(Admin(q))),
            ses.declare_queryable(wire.world_supervise_key(run), lambda q: put(Supervise(q), False)),
        ]
        self.sense_pub = {
            i: ses.declare_publisher(wire.agent_key(run, i, "sense"), express=True) for i in self.cfg.scenario.ids
        }
        self.truth_pub = ses.declare_publisher(wire.truth_key(run))
        self.events_pub = ses.declare_publisher(wire.events_key(run))
        self.control_pub = ses.declare_publisher(wire.world_control_key(run))
        self.token = ses.liveliness().declare_token(wire.world_alive_key(run))

    def add_sense(self, aid: int) -> None:
        """The publisher of agent `aid`'s frames (an agent added at run time, world/joins.py)."""
        self.sense_pub[aid] = self.session.declare_publisher(wire.agent_key(self.cfg.run, aid, "sense"), express=True)

    def send_control(self, payload: bytes) -> None:
        """To the launcher, on world/control (a scripted fault to carry out, world/clock.py)."""
        self.control_pub.put(payload)

    def _close(self) -> None:
        """The end notice, then the session closed once the agents have left (at most
        END_WAIT_S): closing at once could take the notice down with the links before zenoh
        sent it (seen on a loaded machine), and an agent that sees the world's token go
        without it exits 4, "the world vanished", instead of 0."""
        try:
            self.control_pub.put(wire.encode_end(self.core.tick))
            self._wait_agents_gone(END_WAIT_S)
        except Exception:
            pass
        self.session.close()

    def _wait_agents_gone(self, timeout: float) -> None:
        """Until no agent token of the run is left (each agent leaves on the end notice), or
        `timeout` s: a stopped or unreachable agent does not hold the world up longer."""
        key = wire.agent_key(self.cfg.run, "*", "alive")
        t_end = time.monotonic() + timeout
        while (left := t_end - time.monotonic()) > 0:
            replies = self.session.liveliness().get(key, timeout=min(max(left, 0.05), 0.25))
            if not any(r.ok is not None for r in replies):
                return
            time.sleep(0.02)

    # -- events -----------------------------------------------------------------------------
    def _announce(self, ev: dict[str, Any]) -> None:
        """Every event, as it happens: to observers over zenoh, and to the log."""
        kind, agent, reason = ev["kind"], ev["agent"], ev["reason"]
        try:
            self.event_seq = wire.next_seq(self.event_seq)
            self.events_pub.put(wire.encode_event(ev, self.event_seq))
        except Exception:
            pass
        if self.cfg.progress:
            log.info("t=%8.2fs tick %d: %s agent %s: %s", self.core.time, self.core.tick, kind, agent, reason)

    def publish_frames(self) -> set[int]:
        """Send every active agent its frame of this tick (the same numbers as WorldCore.frames)."""
        c = self.core
        if not self.engine.frames_exact():  # through the fault plan: partition, loss, delay, noise
            delivered = self.engine.frames()
            for aid in c.active_ids():
                if aid not in delivered:
                    self.book[aid].missed += 1  # its frame was lost
            self.frames_sent = {aid: wire.encode_sense(frame) for aid, frame in delivered.items()}
            for aid, buf in self.frames_sent.items():
                self.sense_pub[aid].put(buf)
            self.rec.flush()
            return set(delivered)
        self.engine.mark_frames()  # the same numbers, encoded straight from the arrays
        active = c.active_ids()
        rows = [c.index[aid] for aid in active]
        if c.uses_grid():  # the sensed pairs straight from the grid: no (N, N) matrix made
            i, j, bearing, rng = c.sensed_pairs()
            tx, ty = c.target
            frames = wire.encode_sense_pairs(
                c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, i, j, bearing, rng, c.hops
            )
        else:
            sensed, bearing, rng = c.sensing()
            tx, ty = c.target
            frames = wire.encode_sense_rows(
                c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, sensed, bearing, rng, c.hops
            )
        pubs = self.sense_pub
        for aid, frame in zip(active, frames):
            pubs[aid].put(frame)
        self.frames_sent = dict(zip(active, frames))  # sent again as they are after a stall (world/clock.py)
        self.rec.flush()  # the last tick's recording, while the agents answer these frames
        return set(active)

    def resend_frames(self, aids: Iterable[int]) -> None:
        """This tick's frames again, byte for byte, to agents that have not answered (after a
        stall of the world: the first ones may have been lost with the agents' links). An
        agent answers a repeated frame with the command it already sent (agents/node.py)."""
        for aid in aids:
            buf = self.frames_sent.get(aid)
            if buf is not None:
                self.sense_pub[aid].put(buf)

    def record_and_step(self) -> None:
        self.engine.end_tick(observe=self.publish_truth)

    def publish_truth(self, u: np.ndarray, force: bool = False) -> None:
        """Ground truth for observers, at most every TRUTH_PERIOD s (the world itself
        records every tick; observers only draw and report)."""
        now = time.monotonic()
        if not force and now - self.truth_sent < TRUTH_PERIOD:
            return
        c = self.core
        self.truth_sent = now
        self.truth_seq = wire.next_seq(self.truth_seq)
        try:
            self.truth_pub.put(
                wire.encode_truth(
                    c.tick,
                    c.time,
                    c.ids,
                    c.x,
                    c.y,
                    c.heading,
                    u,
                    self.engine.out,
                    cast("list[str]", c.state),
                    self.truth_seq,
                )
            )
        except Exception:  # an observer's problem never stops the world
            pass

    def agent_reports(self, timeout: float = 1.0) -> dict[int, dict]:
        """What each live agent counted itself (from its status), for the summary: malformed
        messages it dropped (`garbage`), non-finite law outputs (`nonfinite`) and, under
        selection = "sticky", losses of its out-neighbour (`losses`, `loss_switches_max`)."""
        reports: dict[int, dict] = {}
        try:
            for aid, st in query_statuses(self.session, self.cfg.run, timeout).items():
                if aid in self.book:
                    reports[aid] = {k: st[k] for k in wire.STATUS_COUNTERS if type(st.get(k)) is int and st[k] >= 0}
        except Exception:  # the summary is written whatever the agents do
            pass
        return reports

    def discard_recording(self) -> None:
        """The run never started (no endpoint): leave no empty recording behind."""
        rec = self.rec
        if getattr(rec, "path", None) is not None and rec.rows == 0:
            try:
                rec.close()
            except RecordingError:
                pass
            rec.path.unlink(missing_ok=True)

    def finish(self) -> dict[str, Any] | None:
        """Record the final state row and write the results; returns the summary."""
        self.inbox.admin_due(now=True)  # pauses and resumes held back by their budget (world/inbox.py)
        c = self.core
        if c.tick <= self.ticks and self.engine.rec.rows <= c.tick:
            self.engine.close()
            self.publish_truth(np.full(len(c.ids), np.nan), force=True)
        if self.cfg.out_dir is None:
            return None
        own = self.agent_reports()
        agent_extra = {
            str(aid): agent_figures(b, c.tick, self.cfg.clock == "realtime", **own.get(aid, {}))
            for aid, b in self.book.items()
        }
        st, clock = self.state, self.clock
        wall = clock.wall_ticks
        plant = (
            {}
            if self.cfg.plant is None
            else {
                "robots": self.cfg.plant.figures(),
                # steps the robots stood still for after a stall (world/clock.py), the first of them
                "held_ticks": self.engine.held_total,
                "first_held_tick": self.engine.first_held_tick,
            }
        )
        start = next((e.get("wall_time") for e in self.engine.events if e["kind"] == EventKind.START), None)
        result = self.engine.result(
            {
                "engine": "up",
                "run": self.cfg.run,
                "endpoint": self.cfg.listen,
                "clock": self.cfg.clock,
                "time_scale": self.cfg.time_scale,
                "completed": self.stopped_by is None and c.tick >= self.ticks,
                "stopped_by_signal": self.stopped_by,
                "garbage_messages": st.garbage,
                "ignored_messages": st.ignored,
                "rejected_commands": c.rejected,
                "over_limit": st.over_limit,
                "wall_time": wall,
                "start_wall_time": start,  # unix s at tick 0 (None: the run never started)
                "ticks_per_second": (c.tick / wall) if wall else None,
                "tick_ms": clock.tick_times.summary_ms(),  # each tick's wall time (world/clock.py)
                "deadline_restarts": clock.restarts,
                "late_ticks": clock.late_ticks,  # realtime: ticks started > half a period late (re-anchored)
                "skipped_ticks": clock.skipped_ticks,  # realtime: whole periods the clock fell behind there
                **clock.reproducibility(),
                **plant,
            },
            agent_extra,
        )
        return write_run(result, self.cfg.out_dir)
