"""Ctrl-C and the batch scheduler's SIGTERM: the farm ends tidily, the results file keeps every
finished case.

mpiexec and srun deliver the signal to every rank. Left to Python, each rank would raise
KeyboardInterrupt wherever it happens to be, some inside a collective or a PETSc callback, and the
job would end in MPI assertion and PETSc error messages. Instead, during the farm, the ranks other than
0 ignore SIGINT and SIGTERM, and world rank 0 commits the finished cases, prints one line and ends
the job with exit status 128 + signal number (MPI_Abort on several ranks). A signal that arrives
while rank 0's own thread writes the results file takes effect once the write is done.
"""
import signal
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interruptible:
    """``with Interruptible(hub):`` the farm's handlers for SIGINT and SIGTERM (``hub``: the
    Hub on world rank 0, None elsewhere); the previous handlers come back on exit."""

    def __init__(self, hub):
        self.hub = hub
        self.saved = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():   # only there can Python set them
            handler = self.handle if self.hub is not None else signal.SIG_IGN
            self.saved = {s: signal.signal(s, handler) for s in SIGNALS}
        return self

    def __exit__(self, *exc):
        for s, h in self.saved.items():
            signal.signal(s, h)
        self.saved = {}
        return False

    def handle(self, signum, frame=None):
        if self.hub.aborting:       # a second signal (mpiexec forwards the terminal's): nothing new
            return
        coord = self.hub.coord
        if coord.writing == threading.get_ident():       # interrupted our own write: finish it first
            coord.after_write = lambda: self.handle(signum)
            return
        self.hub.abort("", code=128 + signum, head=f"interrupted by {signal.Signals(signum).name}",
                       unwind=False)
