"""One case solved by one group: the solve, its /cases row and its fields file.

The row is built by :mod:`vecontact.rows` from the case's theory row, the solver's result and the
morphology of the contact set; the contact set (and any requested field, every ``downsample``-th
point) is gathered to the group's leader (:func:`gather_rows`), which computes the morphology and
writes the fields file itself (atomically; the coordinator only links it).
"""
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from vecontact.io.results import write_fields_file
from vecontact.rows import solved_row

#: FFT pairs timed after each case on its grid and ranks (``SlabFFT.time_pair``; the fastest is
#: ``raw_pair_seconds`` in /diagnostics): the machine's pace while the case ran, which separates a
#: code's cost from the machine's day (benchmarks/study_cost.py).  A few seconds a case at 4096^2,
#: not counted in ``seconds``; 0: no probe.
PACE_PAIRS = 3


@dataclass(frozen=True)
class Setup:
    """What every solve of a job shares (the same on every rank). ``L``: period of the surface (m);
    ``store``: the local fields the solver returns; ``fields``: those written per case."""
    L: float
    modulus: object
    tolerance: float
    method: str
    coarse: object
    max_iterations: object
    petsc_options: dict
    store: tuple
    fields: tuple
    downsample: int
    output: str

    @classmethod
    def from_job(cls, job, petsc_options):
        num = job.numerics
        fields = tuple(num.fields)
        # the pressure always: its contact set gives the morphology columns
        store = tuple(f for f in ("pressure", "gap", "displacement") if f in fields or f == "pressure")
        return cls(L=job.surface.length, modulus=job.material.modulus(), tolerance=num.tolerance,
                   method=num.solver, coarse=num.coarse, max_iterations=num.max_iterations,
                   petsc_options=petsc_options, store=store, fields=fields,
                   downsample=int(num.downsample), output=job.output)


def solve_case(group, fft, heights, case, theory, setup, warm=None):
    """Solve ``case`` on the ranks of ``group`` (slab FFT ``fft``, local surface ``heights`` in m),
    warm-started from ``warm`` (the previous ContactResult of its chain, or None).

    Returns (ContactResult, row, fields link, raw pair seconds): the row is ``theory`` filled with
    the solve (the morphology columns on the group's leader only), the link None off the leader or
    without fields, the last the fastest of PACE_PAIRS pairs timed after the solve (None if 0).
    """
    from vecontact.analysis.morphology import contact_morphology
    from vecontact.solver import solve_contact
    res = solve_contact(fft, setup.L, heights, setup.modulus, case.velocity, case.pressure,
                        tolerance=setup.tolerance, method=setup.method,
                        petsc_options=setup.petsc_options or None, warm=warm, coarse=setup.coarse,
                        max_iterations=setup.max_iterations, store=setup.store)
    contact = gather_rows(group, fft, (res.pressure > 0).astype(np.uint8))
    morphology = contact_morphology(contact, setup.L / fft.N) if group.rank == 0 else None
    row = solved_row(theory, res, fft.N, group.size, morphology)
    link = write_fields(group, fft, case, res, row, setup, contact) if setup.fields else None
    pace = fft.time_pair(PACE_PAIRS)[0] if PACE_PAIRS else None
    return res, row, link, pace


def write_fields(group, fft, case, res, row, setup, contact):
    """Gather every k-th point of each requested field to the leader, which writes the file; the
    contact map is the one already gathered for the morphology (``contact``, full resolution on the
    leader). Returns the file's link on the leader, None elsewhere."""
    k = setup.downsample
    arrays = {}
    for name in setup.fields:
        if name == "contact":
            arrays[name] = contact[::k, ::k] if group.rank == 0 else None
            continue
        src = getattr(res, name)
        if src is not None:
            arrays[name] = gather_rows(group, fft, np.asarray(src, np.float64), k)
    if group.rank != 0:
        return None
    attrs = {"q1": case.q1, "seed": case.seed, "velocity": case.velocity, "pressure": case.pressure,
             "N": fft.N, "downsample": k, "L": setup.L, "spacing": setup.L * k / fft.N,
             "area": float(row["area"]), "mu": float(row["mu"]), "converged": bool(row["converged"]),
             "units": "pressure: Pa; gap, displacement: m; contact: 1 where p > 0; spacing, L: m",
             "layout": "[x, y], axis 0 = sliding direction x; every downsample-th grid point"}
    return write_fields_file(setup.output, case.name, arrays, attrs)


def gather_rows(group, fft, local, k=1):
    """Every k-th row and column of a slab-distributed field (local rows [row_start, row_stop) of an
    N x N grid), gathered to the group's rank 0 (None elsewhere). uint8 or float64 fields."""
    first = -(-fft.row_start // k) * k
    part = np.ascontiguousarray(local[np.arange(first, fft.row_stop, k) - fft.row_start, ::k])
    if group.size == 1:
        return part
    nrows = np.array(group.allgather(part.shape[0]))
    counts = nrows * part.shape[1]
    displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
    full = np.empty((int(nrows.sum()), part.shape[1]), part.dtype) if group.rank == 0 else None
    mpitype = MPI.UNSIGNED_CHAR if part.dtype == np.uint8 else MPI.DOUBLE
    group.Gatherv(part, [full, counts, displs, mpitype] if group.rank == 0 else None, root=0)
    return full
