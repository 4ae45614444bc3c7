"""The task farm's transport: the hub on world rank 0, every rank's link to it, the waits and the abort.

Hub
---
World rank 0 runs the coordinator (:class:`~vecontact.farm.schedule.Coordinator`) in a thread when
MPI gives ``MPI_THREAD_MULTIPLE``; with a lower thread level rank 0 is a dedicated coordinator and
does not compute. The leader of every group asks it for work (a :class:`Request`, on a duplicate
of the world communicator, ``ctl``) and reports each finished case (its results row, a few hundred
bytes); rank 0's own group asks in-process. Between requests the hub commits the results file.
The group hears its leader's answer by a broadcast (:meth:`Link.ask`).

Polling
-------
Every wait here polls with short, growing sleeps instead of blocking in MPI: MPICH spins in blocking
calls, and idle ranks and the coordinator thread must leave the cores to the ranks that compute.

Abort
-----
An exception on any rank is sent to the hub (:meth:`Link.fail`), which commits the finished cases,
prints the case and the traceback once and calls ``MPI_Abort``: the job ends promptly (no rank is
left waiting in a collective). A failing rank that the hub does not abort within ``FAIL_GRACE``
aborts by itself.
"""
import os
import sys
import threading
import time
import traceback
from typing import NamedTuple, Optional

import numpy as np
from mpi4py import MPI

from vecontact.farm.schedule import Finished, Split, Stop, Work

TAG_REQ, TAG_REP, TAG_FAIL = 7101, 7102, 7103
ABORT_DELAY = 1.0   # s between printing an error and MPI_Abort
COMMIT_RETRIES, COMMIT_RETRY_DELAY = 3, 2.0   # transient write errors of the results file (s)
FAIL_GRACE = 20.0   # s a failing rank waits for the coordinator to abort before aborting itself
ACTIONS = (Stop, Work, Split)    # an action's code in the broadcast buffer: its index here
WIDTH = 1 + max(len(kind._fields) for kind in ACTIONS)


class Request(NamedTuple):
    """A group leader's message to the hub: its group's size and what it has just finished."""
    size: int
    finished: Optional[Finished] = None


def wait(test, lo=1e-4, hi=5e-3):
    """Poll ``test()`` with sleeps growing from ``lo`` to ``hi`` s (never spin in MPI)."""
    d = lo
    while not test():
        time.sleep(d)
        d = min(2 * d, hi)


def pack(action, buf):
    """Write ``action`` (Work, Split or Stop) into the int64 buffer ``buf`` of length WIDTH."""
    buf[:] = 0
    buf[0] = ACTIONS.index(type(action))
    buf[1:1 + len(action)] = action


def unpack(buf):
    """The action written by :func:`pack`."""
    kind = ACTIONS[int(buf[0])]
    return kind(*(int(x) for x in buf[1:1 + len(kind._fields)]))


def abort(comm, text, code=1, unwind=True):
    """Print ``text`` to stderr and end the job with exit status ``code``: MPI_Abort on several
    ranks; on one, SystemExit (``unwind``) or ``os._exit`` (from a signal handler, which may run inside
    a PETSc callback: PETSc would report the SystemExit as an error of its own)."""
    try:
        sys.stdout.flush()
    except Exception:
        pass
    sys.stderr.write(text)
    sys.stderr.flush()
    if comm.size == 1:
        if unwind:
            raise SystemExit(code)
        os._exit(code)
    # mpiexec (hydra) tears the job down as soon as it hears of the abort and can drop output still
    # in flight from the ranks: give it a moment to forward the message first
    time.sleep(ABORT_DELAY)
    comm.Abort(code)


class Hub:
    """The coordinator's transport on world rank 0: in-process requests from rank 0's own group,
    polled messages (in a thread, or in the main thread of a dedicated rank 0) from the others;
    also the single point of abort."""

    def __init__(self, coord, ctl, comm):
        self.coord = coord
        self.ctl = ctl
        self.comm = comm
        self.thread = None
        self._abort_lock = threading.Lock()
        self.aborting = False
        self.busy = 0.0             # s spent answering and committing

    def start(self):
        self.thread = threading.Thread(target=self.loop, name="vecontact-coordinator", daemon=True)
        self.thread.start()

    def request(self, gsize, finished):
        """Rank 0's own group asks in-process."""
        action = self.coord.request(0, gsize, finished)
        if self.thread is None:     # one rank: no coordinator thread, commit here
            self.coord.commit_pending()
        return action

    def loop(self):
        """Answer requests and commit the results file until every group has stopped."""
        try:
            d = 1e-4
            failures = 0
            st = MPI.Status()
            while True:
                if self.ctl.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=st):
                    t = time.perf_counter()
                    src, tag = st.Get_source(), st.Get_tag()
                    msg = self.ctl.recv(source=src, tag=tag)
                    if tag == TAG_FAIL:
                        self.abort(msg)
                    elif tag == TAG_REQ:
                        action = self.coord.request(src, msg.size, msg.finished)
                        self.ctl.send(action, dest=src, tag=TAG_REP)
                    self.busy += time.perf_counter() - t
                    d = 1e-4
                    continue
                t = time.perf_counter()
                try:
                    committed = self.coord.commit_pending()
                    failures = 0
                except OSError as exc:      # e.g. a file-system hiccup: retry, then give up
                    failures += 1
                    if failures > COMMIT_RETRIES:
                        raise
                    sys.stderr.write(f"vecontact: warning: writing the results file failed ({exc}); "
                                     f"retrying in {COMMIT_RETRY_DELAY:g} s\n")
                    sys.stderr.flush()
                    time.sleep(COMMIT_RETRY_DELAY)
                    continue
                if committed:
                    self.busy += time.perf_counter() - t
                    continue
                if self.coord.active <= 0:
                    break
                time.sleep(d)
                d = min(2 * d, 1e-2)
        except BaseException:
            self.abort("vecontact: error: the coordinator / results writer on rank 0 failed:\n"
                       + traceback.format_exc())

    def abort(self, text, code=1, head="job aborted", unwind=True):
        """Commit what is finished, print ``text`` and one line (``head``; what the file keeps)
        once, end the whole job with exit status ``code`` (see :func:`abort`)."""
        with self._abort_lock:
            if self.aborting:
                while True:
                    time.sleep(1)
            self.aborting = True
        kept = f"vecontact: {head}; "
        locked = False
        try:
            locked = self.coord.lock.acquire(timeout=30)
            if locked:      # held until the end: no row arrives after the count below
                self.coord.commit_pending()
                kept += (f"{self.coord.ndone} finished cases are kept in the results file: rerun the "
                         "same command to resume\n")
            else:
                kept += "the results file keeps the cases committed before (its writer did not answer)\n"
        except BaseException:
            kept += "committing the finished cases failed too\n"
        try:
            abort(self.comm, (text.rstrip("\n") + "\n" if text else "") + kept, code, unwind)
        finally:            # reached only when one rank unwinds (SystemExit)
            if locked:
                self.coord.lock.release()


class Link:
    """A rank's line to the hub (``hub``: the Hub on world rank 0, None elsewhere)."""

    def __init__(self, comm, ctl, hub=None):
        self.comm = comm
        self.ctl = ctl
        self.hub = hub
        self.buf = np.zeros(WIDTH, dtype=np.int64)

    def ask(self, group, finished=None):
        """The group's next action: the leader asks the hub, the group hears it (Ibcast)."""
        if group.rank == 0:
            if self.hub is not None:
                action = self.hub.request(group.size, finished)
            else:
                self.ctl.send(Request(group.size, finished), dest=0, tag=TAG_REQ)
                wait(lambda: self.ctl.Iprobe(source=0, tag=TAG_REP))
                action = self.ctl.recv(source=0, tag=TAG_REP)
            pack(action, self.buf)
        if group.size > 1:
            wait(group.Ibcast(self.buf, root=0).Test)
        return unpack(self.buf)

    def fail(self, text):
        """Report an error: the hub prints ``text`` once and aborts the job. Does not return."""
        if self.hub is not None:
            self.hub.abort(text)
        if self.comm.size == 1:
            abort(self.comm, text)
        req = self.ctl.isend(text, dest=0, tag=TAG_FAIL)
        t0 = time.time()
        while time.time() - t0 < FAIL_GRACE:     # the hub aborts us all
            if req.Test():
                pass
            time.sleep(0.05)
        abort(self.comm, text)
