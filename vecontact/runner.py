"""``vecontact run``: a job from validated YAML to a complete results file.

Every rank validates the job and computes the (cheap) theory; rank 0 alone writes the file.
With ``numerics.enabled`` the task farm (:mod:`vecontact.farm`) solves the cases.
"""
import sys

from mpi4py import MPI

from vecontact import cases as sweep
from vecontact.errors import InputError, ResultsFileError
from vecontact.io.results import ResultsFile
from vecontact.job import physics_hash, to_yaml
from vecontact.physics.modulus import warn_coverage
from vecontact.physics.spectrum import Tabulated


def spectra(job, comm, warn=True):
    """q1 (1/m) -> roughness spectrum C(q) (m^4) of the job's cases, the same on every rank.

    self-affine: the analytic spectrum at each q1; psd: the measured table restricted to the band
    [max(q_min, 2 pi / length), q1] that the system holds (theory and numerics see the same band);
    file: the radially averaged PSD of the surface (one q1: its largest bin). With ``warn``, warns
    (:class:`InputWarning`, rank 0) when a tabulated modulus does not cover the frequencies q v.
    """
    s = job.surface
    if s.spectrum == "self-affine":
        out = {float(q1): sweep.spectrum_for(job, q1) for q1 in s.q1}
    elif s.spectrum == "psd":
        from vecontact.io.psd import read_psd
        table = read_psd(s.file, s.dimension, columns=s.columns)
        out = {float(q1): table.band(s.q0, q1) for q1 in s.q1}
    else:
        from vecontact.core.surface import load
        from vecontact.core.pfft import SlabFFT
        fft = SlabFFT(comm, s.grid(None))
        h = load(fft, s.file, s.dataset)
        try:
            psd = Tabulated.from_surface(fft, h, s.length)
        except ValueError as exc:
            raise InputError("surface.file", str(exc)) from None
        out = {float(psd.q_max): psd}
    if warn and comm.rank == 0:
        warn_coverage(job.material.modulus(), min(p.q_min for p in out.values()),
                      max(p.q_max for p in out.values()), job.sweep.velocity)
    return out


def open_results(job, comm):
    """Rank 0 opens (or reopens for a restart) the results file; errors reach every rank."""
    writer, err = None, None
    if comm.rank == 0:
        try:
            writer = ResultsFile.open(job.output, to_yaml(job), physics_hash(job), comm.size)
        except InputError as exc:
            err = exc
    # the exception object itself does not survive pickling (InputError takes two arguments)
    info = comm.bcast(None if err is None else (isinstance(err, ResultsFileError), err.key, err.problem), root=0)
    if info is not None:
        if err is not None:
            raise err
        raise (ResultsFileError if info[0] else InputError)(info[1], info[2])
    return writer


def select_q1(job, text):
    """The q1 values (1/m) named by ``--q1`` ("8e6,1.6e7"), each one of the job's; None: all."""
    if text is None:
        return None
    known = [float(q) for q in job.surface.q1]
    out = []
    for item in filter(None, (t.strip() for t in str(text).split(","))):
        try:
            q = float(item)
        except ValueError:
            raise InputError("--q1", f"{item!r} is not a number") from None
        match = [x for x in known if abs(x - q) <= 1e-9 * x]
        if not match:
            raise InputError("--q1", f"{item} is not one of the job's q1 ({', '.join(f'{x:g}' for x in known)})")
        out.append(match[0])
    if not out:
        raise InputError("--q1", "names no q1")
    return out


def run(job, comm=MPI.COMM_WORLD, quiet=False, petsc_args=(), only_q1=None):
    """Run the job on ``comm``; ``only_q1`` (a "--q1" comma list) restricts which cases this call solves."""
    only = select_q1(job, only_q1)
    psds = spectra(job, comm)
    cases = sweep.expand(job, psds)
    rows, groups = sweep.theory(job, psds, cases)
    if job.numerics.enabled:     # a value PETSc refuses: an InputError on every rank, nothing written
        from vecontact.farm.run import petsc_options
        from vecontact.solver.snes import check_options
        check_options(petsc_options(job, petsc_args))
    writer = open_results(job, comm)
    if writer is not None:
        for name, (datasets, attrs) in groups.items():
            writer.set_group(name, datasets, attrs)
    if job.numerics.enabled:
        from vecontact.farm import run_numerics
        run_numerics(job, comm, writer, cases, rows, psds, quiet=quiet, petsc_args=petsc_args, only_q1=only)
    elif writer is not None:
        for row in rows.values():
            writer.add_row(row)
        writer.commit(complete=True)
    if comm.rank == 0 and not quiet:
        print(f"vecontact: {len(cases)} cases written to {job.output}", file=sys.stdout, flush=True)
    return len(cases)
