"""A worker process of a study's pool (swarm/study/pool.py): `python -m swarm.study.child`.

It reads pickled `(worker, job)` messages on stdin (a thread reads them as they come: the pool
sends the next job while this one runs) and runs them in turn, answering each on stdout:
first `STARTED` (the job is unpickled, its modules imported: a fresh process's start-up does
not count against a run's time), then `(True, rows)` or `(False, (exception, traceback
text))`; `None` or the end of stdin ends it. What a law prints goes to stderr: stdout carries nothing but the answers.
"""

from __future__ import annotations

import os
import pickle
import queue
import sys
import threading
import traceback
from multiprocessing.connection import Connection

STARTED = (None, None)  # said once a job's modules are imported: its time budget starts then


def serve() -> None:
    answers = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)  # print() of a law or a library: to stderr, never into the answers
    sys.stdout = sys.stderr
    asks = Connection(os.dup(0), writable=False)
    inbox: queue.Queue = queue.Queue()

    def read() -> None:  # always reading, so the pool's send of the next job never waits on this run
        while True:
            try:
                data = asks.recv_bytes()
            except (EOFError, OSError):
                inbox.put(None)
                return
            inbox.put(data)

    threading.Thread(target=read, daemon=True).start()
    while True:
        data = inbox.get()
        message = None if data is None else pickle.loads(data)
        if message is None:
            return
        worker, job = message  # unpickling imported the worker's modules: the run starts now
        answers.send_bytes(pickle.dumps(STARTED))
        try:
            answer = (True, worker(job))
        except Exception as e:
            answer = (False, (e, traceback.format_exc()))
        try:
            out = pickle.dumps(answer)
        except Exception:  # an exception that does not pickle: its text
            out = pickle.dumps((False, (RuntimeError(repr(answer[1][0])), answer[1][1])))
        answers.send_bytes(out)


if __name__ == "__main__":
    serve()
