"""``run_numerics``: the task farm from a job's cases to committed rows, on any number of ranks.

Sets up the chains (:mod:`~vecontact.farm.schedule`), the hub and links
(:mod:`~vecontact.farm.transport`) and the workers (:mod:`~vecontact.farm.worker`), runs them in the
mode MPI's thread level allows (coordinator thread on rank 0, or rank 0 dedicated to coordinating),
then commits the last rows and prints the summary (:mod:`~vecontact.farm.progress`).
"""
import time
import traceback
import warnings

import numpy as np
from mpi4py import MPI

from vecontact.farm import progress
from vecontact.farm.interrupt import Interruptible
from vecontact.errors import InputWarning
from vecontact.farm.memory import MEMORY_USE, case_bytes, fits, memory_per_rank
from vecontact.farm.schedule import Coordinator, build_chains
from vecontact.farm.transport import Hub, Link, abort, wait
from vecontact.farm.worker import Worker
from vecontact.solver.settings import SolverSettings


def petsc_options(job, petsc_args):
    """job's numerics.petsc merged with the command line's PETSc options (command line wins)."""
    from vecontact.solver.options import parse
    opts = dict(job.numerics.petsc or {})
    if petsc_args:
        opts.update(parse(list(petsc_args), "numerics.petsc"))
    return opts


def _warn_memory(chains, memory, settings):
    """An InputWarning for every grid whose cases, on the ranks they get, may need more memory a rank
    than it may fill (memory.fits: case_bytes against MEMORY_USE of ``memory``, the bytes a rank may
    use): auto at its largest rank count, or a fixed ranks_per_case. The estimate bounds the measured
    peaks (up to 1.6x them at 8192²), so such a case may still fit."""
    for N, g in sorted({(ch.N, ch.g) for ch in chains}):
        if not fits(N, g, memory, settings):
            warnings.warn(
                f"numerics.ranks_per_case: N={N} on {g} rank{'s' if g > 1 else ''}: a case may need "
                f"{case_bytes(N, g, settings) / 1e9:.1f} GB a rank, more than the "
                f"{MEMORY_USE * memory / 1e9:.1f} GB a rank may fill: it may run out of memory (on more "
                f"ranks a case needs less a rank)", InputWarning, stacklevel=2)


def _first_commit(comm, writer):
    """Write the file (theory, finished rows) before any solve: an unwritable output is found now,
    as a one-line error on every rank, not after the first case."""
    err = None
    if comm.rank == 0 and writer is not None:
        try:
            writer.commit()
        except Exception as exc:
            err = f"cannot write {writer.path} ({type(exc).__name__}: {exc})"
    err = comm.bcast(err, root=0)
    if err:
        from vecontact.errors import ResultsFileError
        raise ResultsFileError("output", err)


def _init_petsc(job):
    """PetscInitialize is collective on COMM_WORLD: do it on every rank before the groups split."""
    if job.numerics.solver != "snes":
        return
    try:
        from petsc4py import PETSc  # noqa: F401
    except ImportError:
        pass


def run_numerics(job, comm, writer, cases, rows, psds, quiet=False, petsc_args=(), only_q1=None):
    """Solve every unfinished case of the job on ``comm`` (only those at the q1 values in
    ``only_q1`` when it is given) and commit each row as it finishes. ``rows``: case key -> theory
    row; ``psds``: q1 -> spectrum; ``writer``: the ResultsFile on rank 0 (None elsewhere).
    Returns the number of cases solved (on rank 0; None elsewhere)."""
    t_start = time.perf_counter()
    options = petsc_options(job, petsc_args)     # bad options: InputError on every rank
    rank, size = comm.rank, comm.size
    num = job.numerics
    todo = np.ones(len(cases), dtype=bool)
    if rank == 0 and writer is not None:
        done = writer.done()
        todo = np.array([c.key not in done for c in cases], dtype=bool)
    todo = comm.bcast(todo, root=0)
    if only_q1 is not None:
        todo &= np.array([c.q1 in only_q1 for c in cases], dtype=bool)
    if rank == 0 and writer is not None:
        writer.note_run(petsc_options=options, ranks_per_case=str(num.ranks_per_case))
    _first_commit(comm, writer)
    threaded = size == 1 or MPI.Query_thread() >= MPI.THREAD_MULTIPLE
    nwork = size if threaded else size - 1
    Ns = {q1: job.surface.grid(q1) for q1 in psds}
    memory = memory_per_rank(comm)
    settings = SolverSettings().with_options(options)   # checked by petsc_options: -vc_ budgets
    chains = build_chains(cases, todo, lambda q1: Ns[q1], nwork, num.ranks_per_case, memory, settings)
    if rank == 0:
        _warn_memory(chains, memory, settings)
    _init_petsc(job)
    ctl = comm.Dup()
    fin = comm.Dup()
    hub = coord = None
    if rank == 0:
        ndone = len(writer.done()) if writer is not None else 0
        report = None if quiet else progress.Progress(cases, chains, nranks=nwork, total=ndone + int(todo.sum()))
        coord = Coordinator(chains, cases, writer, ndone=ndone, progress=report)
        hub = Hub(coord, ctl, comm)
        if not quiet:
            rule = {ch.N: ch.g for ch in chains}
            print(progress.start_line(len(cases), ndone, int(todo.sum()), len(chains), size,
                                      num.ranks_per_case, rule, threaded, memory), flush=True)
    worker = Worker(job, comm, Link(comm, ctl, hub), cases, rows, psds, Ns, chains, options)
    with Interruptible(hub):     # Ctrl-C, SIGTERM: rank 0 commits and ends the job
        try:
            if threaded:
                if rank == 0 and size > 1:
                    hub.start()
                worker.run(comm.Dup())
                if rank == 0 and hub.thread is not None:
                    while hub.thread.is_alive():
                        hub.thread.join(0.05)
            else:
                group = comm.Split(0 if rank > 0 else MPI.UNDEFINED, key=rank)
                if rank == 0:
                    hub.loop()
                else:
                    worker.run(group)
        except BaseException:
            worker.fail(traceback.format_exc())
        # all groups stopped: the last rows, the summary
        if rank == 0:
            try:
                coord.commit_pending(complete=writer is not None and len(writer.done()) >= len(cases))
            except BaseException:
                abort(comm, "vecontact: error: writing the results file failed:\n" + traceback.format_exc())
    wall = time.perf_counter() - t_start
    busy = fin.gather(worker.busy, root=0)
    if rank == 0 and not quiet:
        print(progress.summary(coord, hub.busy, busy, wall, threaded), flush=True)
    wait(fin.Ibarrier().Test, hi=2e-2)
    for c in (ctl, fin):
        c.Free()
    return coord.nsolved if coord is not None else None
