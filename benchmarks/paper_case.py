"""The benchmarks' case: the surfaces and compound of jobs/paper.yaml (Scaraggi & Persson 2015;
docs/conventions.md §2), read from the job file, so that a benchmark's N x N surface is the study's at
q1 = N / (2 null_band) q0 (N = 512 ... 4096 for q1 = 32 ... 256 q0), bit for bit.

Units: SI (m, 1/m, Pa, m/s).  Importing this module imports no vecontact code; each function does, so
the benchmarks' parent processes (which start the MPI workers) need not.
"""
import functools
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
JOB_FILE = os.path.join(ROOT, "jobs", "paper.yaml")


@functools.lru_cache(maxsize=None)
def job():
    """jobs/paper.yaml, resolved (vecontact.job.load; read once)."""
    from vecontact import job as jobs
    return jobs.load(JOB_FILE)


def q1_of(N):
    """The spectrum's cut-off (1/m) of the study's N x N grid."""
    s = job().surface
    return N / (2 * s.null_band) * s.q0


def period():
    """The side L of the periodic square (m): 2 pi / q0."""
    return job().surface.length


def spectrum(N):
    """The self-affine C(q) (m^4) of the N x N grid (cases.spectrum_for at q1_of(N))."""
    from vecontact.cases import spectrum_for
    return spectrum_for(job(), q1_of(N))


def compound():
    """The Havriliak-Negami rubber of the study (E0 3 MPa, Einf 3 GPa, nu 0.5)."""
    return job().material.modulus()


def elastic():
    """The elastic limit of the compound: E = E0, the same nu."""
    from vecontact.physics.modulus import Elastic
    m = compound()
    return Elastic(m.E0, m.nu)


def surface(fft, seed=1):
    """The study's realisation ``seed`` on the SlabFFT ``fft`` (its local rows, m)."""
    from vecontact.core.surface import generate
    s = job().surface
    return generate(fft, s.length, spectrum(fft.N), seed, amplitudes=s.amplitudes)


def case(N, seed=1, comm=None, planner="estimate"):
    """(fft, L, h, compound): a SlabFFT on ``comm`` (default one rank), the period, the surface of
    ``seed`` and the compound."""
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    fft = SlabFFT(MPI.COMM_SELF if comm is None else comm, N, planner=planner)
    return fft, period(), surface(fft, seed), compound()


__all__ = ["JOB_FILE", "case", "compound", "elastic", "job", "period", "q1_of", "spectrum", "surface"]
