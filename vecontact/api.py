"""The Python API of vecontact: ``import vecontact as vc`` (docs/api.md).

Five lines from a user's own scan and compound to Persson's theory and the exact solution::

    import vecontact as vc
    s = vc.read_topography("scan.x3p")                  # any instrument format; heights in m
    E = vc.modulus("table", file="dma.csv", frequency_unit="Hz")
    print(vc.theory(s, E, velocity=0.01, pressure=2e5))                # A/A0, mu, xi
    print(vc.solve(s, E, velocity=0.01, pressure=2e5).summary())       # the exact solution

Units are SI throughout: lengths and heights in m, wavevectors in 1/m, C(q) in m^4, moduli and
pressures in Pa, velocities in m/s, frequencies in rad/s. Bad input raises :class:`InputError`
(``.key``, ``.problem``), the same one-line messages the command line prints. Jobs are
:class:`vecontact.jobtypes.Job` values (frozen; ``job.to_dict()`` is the resolved YAML job, as stored
in every results file).
"""
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from vecontact import job as jobs
from vecontact.errors import InputError, InputWarning
from vecontact.jobtypes import Job

__all__ = ["load_job", "make_job", "Job", "run", "read_results", "plot_results", "surface", "read_topography",
           "read_psd", "self_affine", "modulus", "theory", "solve", "Surface", "Theory", "InputError",
           "InputWarning", "ConvergenceWarning", "REFERENCE_COMPOUND"]

#: The reference tread compound of docs/conventions.md §3 (Havriliak-Negami): ``vc.modulus(**REFERENCE_COMPOUND)``.
REFERENCE_COMPOUND = {"model": "havriliak-negami", "E0": 3.0e6, "Einf": 3.0e9, "alpha": 0.5, "beta": 0.5,
                      "tau": 1.0e-10, "nu": 0.5}


class ConvergenceWarning(UserWarning):
    """:func:`solve` did not converge: the result's numbers are not results (see its ``reason``)."""


# ------------------------------------------------------------------------------------------------
# jobs
def load_job(path, output=None):
    """Read and validate a YAML job file; returns the resolved :class:`~vecontact.jobtypes.Job`
    (every default filled in, paths absolute). ``output`` overrides the job's results file."""
    return jobs.load(os.fspath(path), output=output)


def make_job(*, output, surface, material, sweep, theory=None, numerics=None, base="."):
    """Validate a job given as its sections (dicts, the keys of the YAML job file); returns the
    resolved :class:`~vecontact.jobtypes.Job`. Relative paths are relative to ``base`` (default: the
    current folder)."""
    raw = {"output": output, "surface": surface, "material": material, "sweep": sweep}
    raw.update({k: v for k, v in (("theory", theory), ("numerics", numerics)) if v is not None})
    if isinstance(output, str) and not os.path.isabs(output):
        raw["output"] = os.path.abspath(os.path.join(base, output))
    return jobs.resolve(raw, os.path.abspath(base))


def _job(job):
    """A resolved job from a path, from load_job / make_job, or a resolved job's dict (``to_dict()``,
    a results file's ``job_yaml``)."""
    if isinstance(job, (str, os.PathLike)):
        return load_job(job)
    if isinstance(job, Job):
        return job
    resolved = (isinstance(job, dict) and isinstance(job.get("surface"), dict) and "seeds" in job["surface"]
                and isinstance(job.get("numerics"), dict) and "enabled" in job["numerics"])
    if not resolved:
        raise InputError("job", "pass a job file path, or a job from vc.load_job or vc.make_job")
    return Job.from_dict(job)


def run(job, comm=None, quiet=True, plot=False):
    """Run a job (a path, or a job from :func:`load_job` / :func:`make_job`): the theory for every
    case and, with ``numerics.enabled``, the exact solutions. ``comm``: an mpi4py communicator
    (default COMM_WORLD: serial in a plain Python session, parallel under mpiexec). Resumes a
    results file of the same job. ``plot``: also draw the figures. Returns the results path."""
    from mpi4py import MPI
    from vecontact.runner import run as run_job
    job = _job(job)
    comm = MPI.COMM_WORLD if comm is None else comm
    run_job(job, comm, quiet=quiet)
    if plot and comm.rank == 0:
        plot_results(job.output)
    return job.output


def read_results(path, as_frame=None):
    """The ``/cases`` table of a results file, one row per (q1, seed, velocity, pressure).

    A pandas DataFrame (units in ``df.attrs["units"]``) when pandas is installed, else a numpy
    structured array; ``as_frame=False`` always gives the array, ``as_frame=True`` insists on pandas.
    Columns and units: docs/reading-results.md.
    """
    import json
    from vecontact.io.results import open_for_reading
    with open_for_reading(os.fspath(path)) as f:
        cases = f["cases"][()]
        units = json.loads(f["cases"].attrs.get("units", "{}"))
    if as_frame is False:
        return cases
    try:
        import pandas as pd
    except ImportError:
        if as_frame:
            raise InputError("as_frame", "pandas is not installed (pip install pandas)") from None
        return cases
    frame = pd.DataFrame(cases)
    frame.attrs["units"] = units
    return frame


def plot_results(path, outdir=None):
    """Draw the paper's figures from a results file (PNG files in ``outdir``, default next to the
    file); returns their paths. (Not ``vc.plot``: that name is the module vecontact.plot.)"""
    from vecontact.plot import plot_results as draw
    return draw(os.fspath(path), outdir)


# ------------------------------------------------------------------------------------------------
# surfaces and spectra
@dataclass
class Surface:
    """A periodic rough surface: ``heights`` (N, N) float64 in m, axis 0 = x = the sliding
    direction; ``length``: the period L in m (grid spacing L / N); ``info``: where it came from."""
    heights: np.ndarray
    length: float
    info: dict = field(default_factory=dict)

    @property
    def N(self):
        """Grid points per side."""
        return int(self.heights.shape[0])

    def _fft(self):
        from mpi4py import MPI
        from vecontact.core.pfft import SlabFFT
        return SlabFFT(MPI.COMM_SELF, self.N)

    def psd(self):
        """The radially averaged power spectrum (Persson's C(q), q in 1/m, C in m^4) as a
        :class:`vecontact.physics.spectrum.Tabulated`: what the theory uses for this surface."""
        from vecontact.physics.spectrum import Tabulated
        try:
            return Tabulated.from_surface(self._fft(), self.heights, self.length)
        except ValueError as exc:
            raise InputError("surface", str(exc)) from None

    def statistics(self):
        """dict: mean, hrms (m), slope_rms (full 2-D gradient, spectral), min, max (m)."""
        from vecontact.core.surface import statistics
        return statistics(self._fft(), self.heights, self.length)


def read_topography(path, channel=None, length=None):
    """A surface from a file, ready for :func:`solve` and :func:`theory`.

    Instrument files (x3p, sur, datx, opd, plu, Gwyddion, Digital Instruments and every format
    SurfaceTopography reads; extra ``vecontact[topography]``) bring their size and units; they
    are cropped to a square, detrended and made periodic (docs/inputs.md); ``channel`` names the
    height channel. ``.npy`` / ``.h5`` files hold N x N heights in m used as they are; give their
    period ``length`` (m) (``channel``: the HDF5 dataset).
    """
    from vecontact.io.topography import is_instrument_file, read_topography as read_scan
    path = os.fspath(path)
    if is_instrument_file(path):
        if length is not None:
            raise InputError("length", "an instrument file states its own size")
        h, L, info = read_scan(path, channel)
        return Surface(h, L, dict(info, file=os.path.abspath(path)))
    if length is None:
        raise InputError("length", f"{os.path.basename(path)} holds heights only: give its period length (m)")
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import load
    from vecontact.io.surfaces import file_grid_size
    L = jobs._number({"length": length}, "length", "", lo=0, lo_open=True)
    h = load(SlabFFT(MPI.COMM_SELF, file_grid_size(path, channel)), path, channel)
    return Surface(h, L, {"file": os.path.abspath(path)})


def surface(job, q1=None, seed=None):
    """The surface a job solves on (serial): generated from its spectrum at cut-off ``q1`` (1/m;
    may be left out when the job has one) and realisation ``seed`` (default: the job's first for
    that q1), or read from the job's file. ``job``: a path or a resolved job."""
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    from vecontact.runner import spectra
    job = _job(job)
    s = job.surface
    if s.spectrum == "file":
        return read_topography(s.file, s.dataset, None if s.source is not None else s.length)
    known = ", ".join(f"{x:g}" for x in s.q1)
    if q1 is None and len(s.q1) != 1:
        raise InputError("q1", f"the job has several q1 ({known} 1/m): name one")
    want = s.q1[0] if q1 is None else jobs._number({"q1": q1}, "q1", "")
    match = [x for x in s.q1 if abs(x - want) <= 1e-9 * x]
    if not match:
        raise InputError("q1", f"{want:g} is not one of the job's q1 ({known} 1/m)")
    q1 = match[0]
    seed = s.realisations(q1)[0] if seed is None else jobs._number({"seed": seed}, "seed", "", lo=0,
                                                                   integer=True)
    psd = spectra(job, MPI.COMM_SELF, warn=False)[q1]
    fft = SlabFFT(MPI.COMM_SELF, s.grid(q1))
    h = generate(fft, s.length, psd, seed, amplitudes=s.amplitudes)
    return Surface(h, s.length, {"spectrum": s.spectrum, "q1": q1, "seed": seed})


def read_psd(path, dimension=2, columns=None):
    """A measured power spectrum from a two-column table q (1/m), C: Persson's 2-D C(q) in m^4
    (``dimension=2``) or a line-scan C1D(q) in m^3 (``dimension=1``, converted to 2-D; see
    docs/inputs.md). Returns a :class:`vecontact.physics.spectrum.Tabulated`; bad tables raise
    InputError naming the problem (order, sign, too few rows, units)."""
    from vecontact.io.psd import read_psd as read
    return read(os.fspath(path), dimension, columns=columns)


def self_affine(q0, qr, q1, hurst, *, C0=None, hrms=None):
    """The paper's self-affine spectrum with roll-off (docs/conventions.md §2): q0 <= qr < q1
    (1/m), Hurst exponent 0 < H < 1, and exactly one of C0 (m^4) or hrms (m)."""
    from vecontact.physics.spectrum import SelfAffine
    v = {k: jobs._number({k: x}, k, "surface", lo=0, lo_open=True)
         for k, x in (("q0", q0), ("qr", qr), ("q1", q1))}
    H = jobs._number({"hurst": hurst}, "hurst", "surface", lo=0, hi=1, lo_open=True, hi_open=True)
    if not v["q0"] <= v["qr"] < v["q1"]:
        raise InputError("surface.qr", f"need q0 <= qr < q1, got {q0:g}, {qr:g}, {q1:g}")
    if (C0 is None) == (hrms is None):
        raise InputError("surface.C0", "give exactly one of C0 (m^4) or hrms (m)")
    if C0 is not None:
        return SelfAffine(v["q0"], v["qr"], v["q1"], H, jobs._number({"C0": C0}, "C0", "surface", lo=0, lo_open=True))
    return SelfAffine.from_hrms(v["q0"], v["qr"], v["q1"], H,
                                jobs._number({"hrms": hrms}, "hrms", "surface", lo=0, lo_open=True))


# ------------------------------------------------------------------------------------------------
# the physics
def modulus(model, **params):
    """A viscoelastic modulus E(omega) (callable, omega in rad/s -> complex Pa, with E0, Einf, nu).

    ``model`` and ``params`` are the keys of a job's ``material`` section, checked the same way:
    "elastic" (E0), "sls" (E0, Einf, tau), "prony" (E0, terms), "havriliak-negami" (E0, Einf,
    alpha, beta, tau) or "table" (file; frequency_unit rad/s or Hz, modulus_unit, columns,
    wlf {C1, C2, T_ref, T}, vertical_shift); nu (default 0.5). ``vc.modulus(**REFERENCE_COMPOUND)``
    is the reference tread compound. A model object passes through unchanged; a dict is read as
    the material section.
    """
    return _as_modulus(model, params)


def _as_modulus(model, params=None):
    """A modulus object from a model object, a material dict, or a model name and parameters."""
    params = dict(params or {})
    if callable(model) and hasattr(model, "E0") and not params:
        return model
    if isinstance(model, dict) and not params:
        params = dict(model)
        model = params.pop("model", None)
    return jobs._material({"material": dict(params, model=model)}, os.getcwd()).modulus()


def _spectrum(psd):
    if isinstance(psd, Surface):
        return psd.psd()
    if isinstance(psd, (str, os.PathLike)):
        return read_psd(psd)
    if callable(psd) and hasattr(psd, "moment") and hasattr(psd, "breakpoints"):
        return psd
    raise InputError("psd", f"must be a spectrum (vc.read_psd, vc.self_affine), a vc.Surface or a C(q) file, "
                            f"got {type(psd).__name__}")


def _values(x, name, positive):
    """A scalar or 1-D list of finite numbers >= 0 (> 0 when ``positive``) -> (1-D array, was scalar)."""
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        arr = np.array([np.nan])
    if arr.ndim > 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise InputError(name, f"must be a finite number or a 1-D list of them, got {x!r}")
    if np.any(arr <= 0 if positive else arr < 0):
        raise InputError(name, f"must be {'>' if positive else '>='} 0, got {x!r}")
    return np.atleast_1d(arr), arr.ndim == 0


@dataclass
class Theory:
    """Persson's theory (docs/conventions.md §5) at every (velocity, pressure).

    ``area`` (A/A0 = P(q1)) and ``mu`` have shape (V, P), ``xi`` (effective rms slope) shape (V,),
    ``P`` (the contact probability P(q) at the wavevectors ``q``, 1/m) shape (V, P, Q); an axis is
    dropped where a scalar velocity or pressure was given (plain floats when both were).
    ``velocity`` (m/s), ``pressure`` (Pa), ``gamma``, ``slope_rms`` (of the spectrum) as used.
    """
    area: object
    mu: object
    xi: object
    q: np.ndarray
    P: np.ndarray
    velocity: object
    pressure: object
    gamma: float
    slope_rms: float

    def summary(self):
        def fmt(x):
            x = np.asarray(x)
            return f"{float(x):.5g}" if x.ndim == 0 else np.array2string(x, precision=5)
        return (f"Persson theory (gamma = {self.gamma:g}): v = {fmt(self.velocity)} m/s, sigma0 = "
                f"{fmt(self.pressure)} Pa: A/A0 = {fmt(self.area)}, mu = {fmt(self.mu)}, xi = {fmt(self.xi)}")

    __str__ = summary


def theory(psd, modulus, velocity, pressure, gamma=0.5, nq=None, nphi=None):
    """Persson's theory for a roughness spectrum and a rubber.

    ``psd``: a spectrum (:func:`read_psd`, :func:`self_affine`), a :class:`Surface` (its radial
    PSD) or the path of a 2-D C(q) table; ``modulus``: a model from :func:`modulus` (or its
    keyword dict); ``velocity`` (m/s, >= 0) and ``pressure`` (nominal, Pa, > 0): numbers or 1-D
    lists; ``gamma`` in [0, 1] for S(q); ``nq``, ``nphi``: quadrature (defaults converged to
    1e-4). Returns a :class:`Theory`. Warns (InputWarning) when a tabulated modulus does not cover
    the frequencies q v.
    """
    from vecontact.physics.modulus import warn_coverage
    from vecontact.physics.theory import persson
    spec = _spectrum(psd)
    E = _as_modulus(modulus)
    v, v_scalar = _values(velocity, "velocity", positive=False)
    p, p_scalar = _values(pressure, "pressure", positive=True)
    gamma = jobs._number({"gamma": gamma}, "gamma", "theory", lo=0, hi=1)
    for name, n, lo in (("nq", nq, 16), ("nphi", nphi, 8)):
        if n is not None:
            jobs._number({name: n}, name, "theory", lo=lo, integer=True)
    warn_coverage(E, spec.q_min, spec.q_max, v, key="modulus", stacklevel=2)
    r = persson(spec, E, v, p, gamma=gamma, nq=nq, nphi=nphi)
    index = (0 if v_scalar else slice(None), 0 if p_scalar else slice(None))

    def pick(a):
        a = a[index]
        return float(a) if np.ndim(a) == 0 else a
    return Theory(area=pick(r.area), mu=pick(r.mu), xi=float(r.xi[0]) if v_scalar else r.xi, q=r.q,
                  P=r.P_q[index], velocity=float(v[0]) if v_scalar else v, pressure=float(p[0]) if p_scalar else p,
                  gamma=r.gamma, slope_rms=r.slope_rms)


#: Options of :func:`solve`, passed to :func:`vecontact.solver.solve_contact`.
SOLVE_OPTIONS = ("tolerance", "method", "petsc_options", "coarse", "max_iterations", "store", "warm", "monitor")


def solve(surface, modulus, velocity, pressure, *, length=None, comm=None, fft_planner="measure", **options):
    """The exact steady-sliding contact of the rubber ``modulus`` on the rigid rough ``surface``.

    ``surface``: a :class:`Surface`, or an (N, N) array of heights in m (axis 0 = sliding
    direction x) with its period ``length`` (m); ``velocity`` (m/s, >= 0); ``pressure``: nominal
    pressure sigma0 (Pa, > 0). Serial by default; with ``comm`` (an mpi4py communicator) every
    rank passes the same full surface and the ranks solve together (returned fields are each
    rank's rows). ``options``: tolerance (default 1e-8), method ("snes" or "pk", elastic only),
    petsc_options, coarse, max_iterations, store (fields to return: "pressure", "gap",
    "displacement"), warm (a previous result on the same grid), monitor. ``fft_planner``: the FFTW
    planner of the grid, "measure" (default) or "patient" (faster pairs at large N for minutes of
    planning once per host and N, cached: docs/fft.md, "Planner"); it changes rounding only, as the
    job key ``numerics.fft_planner`` does.

    Returns a :class:`vecontact.solver.ContactResult`: ``area`` (A/A0), ``mu`` (dissipation),
    ``mu_geometric``, ``mean_gap`` (m), ``converged``, ``summary()``... Warns
    (:class:`ConvergenceWarning`) if the solver did not converge.
    """
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.physics.modulus import warn_coverage
    from vecontact.solver import solve_contact
    if isinstance(surface, Surface):
        if length is not None:
            raise InputError("length", "a vc.Surface carries its own length")
        h, L = surface.heights, surface.length
    else:
        if length is None:
            raise InputError("length", "give the period (m) of the height array")
        h, L = surface, jobs._number({"length": length}, "length", "", lo=0, lo_open=True)
    h = np.asarray(h)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or h.shape[0] < 4 or h.dtype.kind not in "fiu":
        raise InputError("surface", f"heights must be a real N x N array with N >= 4, got shape {h.shape}")
    if not np.isfinite(h).all():
        raise InputError("surface", "heights must be finite")
    E = _as_modulus(modulus)
    v = jobs._number({"velocity": velocity}, "velocity", "", lo=0)
    p = jobs._number({"pressure": pressure}, "pressure", "", lo=0, lo_open=True)
    for k in options:
        if k not in SOLVE_OPTIONS:
            raise InputError(k, f"unknown option (allowed: {', '.join(SOLVE_OPTIONS)})")
    jobs._choice({"fft_planner": fft_planner}, "fft_planner", "", jobs.FFT_PLANNERS)
    comm = MPI.COMM_SELF if comm is None else comm
    N = h.shape[0]
    try:
        fft = SlabFFT(comm, N, planner=fft_planner)
    except ValueError as exc:
        raise InputError("comm", str(exc)) from None
    if comm.rank == 0:
        warn_coverage(E, 2.0 * math.pi / L, math.pi * N / L, [v], key="modulus", stacklevel=2)
    local = np.ascontiguousarray(h[fft.row_start:fft.row_stop], dtype=float)
    try:
        res = solve_contact(fft, L, local, E, v, p, **options)
    except ValueError as exc:
        raise InputError("options", str(exc)) from None
    if not res.converged and comm.rank == 0:
        warnings.warn(f"solve: not converged ({res.reason}, residual {res.residual:.2e}): "
                      f"its numbers are not results", ConvergenceWarning, stacklevel=2)
    return res
