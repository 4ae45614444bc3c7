"""A results file read for analysis: the job, Persson's theory per q1 and the /cases table.

Reads the file only (safe while a sweep writes it). Units as in the file: q1 in 1/m, velocity in m/s,
pressure in Pa, areas as fractions A/A0, E0 in Pa. The job's expected cases come from ``/theory``
(pressures of every (q1, v)) and the seeds of the stored job, so a partially complete file is described
as such: which q1 and seeds have converged numerics and which do not.
"""
from dataclasses import dataclass, field, replace

import numpy as np
import yaml

from vecontact.analysis.ensemble import converged_rows, seed_points
from vecontact.io.results import open_for_reading
from vecontact.jobtypes import Job


@dataclass(frozen=True)
class Theory:
    """Persson's theory at one q1 (the file's ``/theory/q1_<i>`` and ``/spectrum/q1_<i>``).

    velocity (V,) m/s; xi (V,) effective rms slope; pressure, area, mu (V, K) at the sweep's pressures;
    curve_pressure, curve_area, curve_mu (V, J) dense curves; spectrum_q (1/m), spectrum_C (m^4);
    hrms (m), slope_rms (dimensionless)."""
    q1: float
    hrms: float
    slope_rms: float
    velocity: np.ndarray
    xi: np.ndarray
    pressure: np.ndarray
    area: np.ndarray
    mu: np.ndarray
    curve_pressure: np.ndarray
    curve_area: np.ndarray
    curve_mu: np.ndarray
    spectrum_q: np.ndarray
    spectrum_C: np.ndarray

    def v_index(self, velocity):
        """Index of one of the sweep's velocities (m/s) in ``velocity``."""
        return int(np.flatnonzero(self.velocity == velocity)[0])


@dataclass
class Study:
    """A results file: ``job`` (the stored :class:`~vecontact.jobtypes.Job`), ``theories`` (sorted by
    q1), ``cases`` (all rows of /cases), ``E0`` (Pa), ``nu``, ``gamma``, ``attrs`` (root attributes:
    updated, complete, git_commit)."""
    path: str
    job: Job
    theories: list
    cases: np.ndarray
    E0: float
    nu: float
    gamma: float
    attrs: dict = field(default_factory=dict)
    _points: np.ndarray = field(default=None, repr=False)

    @property
    def q1s(self):
        return [t.q1 for t in self.theories]

    @property
    def velocities(self):
        return [float(v) for v in self.theories[0].velocity]

    def theory(self, q1):
        return next(t for t in self.theories if t.q1 == q1)

    def seeds(self, q1):
        """The job's seeds at q1 (what a complete sweep has)."""
        return [int(s) for s in self.job.surface.realisations(q1)]

    def converged(self):
        """Converged rows only (status 1): the only rows that are results."""
        return converged_rows(self.cases)

    def points(self):
        """Seed-averaged converged points (:func:`vecontact.analysis.ensemble.seed_points`), cached."""
        if self._points is None:
            self._points = seed_points(self.cases)
        return self._points

    def q1_with_results(self):
        """The q1 (1/m) that have at least one converged case, sorted."""
        return sorted({float(q) for q in self.converged()["q1"]})

    def q1_label(self, q1):
        """'32 q0' (or '8e+06 1/m' when the job has no q0)."""
        q0 = self.job.surface.q0
        return f"{q1 / q0:.0f} q0" if q0 else f"{q1:.3g} 1/m"

    def expected_cases(self):
        """Every (q1, seed, velocity, pressure) of the job."""
        out = []
        for t in self.theories:
            for seed in self.seeds(t.q1):
                for k, v in enumerate(t.velocity):
                    out += [(t.q1, seed, float(v), float(p)) for p in t.pressure[k]]
        return out


def load_study(path):
    """Read a results file into a :class:`Study` (InputError if it is not one)."""
    with open_for_reading(path) as f:
        job = Job.from_dict(yaml.safe_load(f.attrs["job_yaml"]))
        theories = []
        for name in f["theory"]:
            g, s = f["theory"][name], f["spectrum"][name]
            theories.append(Theory(
                q1=float(g.attrs["q1"]), hrms=float(g.attrs["hrms"]), slope_rms=float(g.attrs["slope_rms"]),
                velocity=g["velocity"][()], xi=g["xi"][()], pressure=g["pressure"][()], area=g["area"][()],
                mu=g["mu"][()], curve_pressure=g["curves/pressure"][()], curve_area=g["curves/area"][()],
                curve_mu=g["curves/mu"][()], spectrum_q=s["q"][()], spectrum_C=s["C"][()]))
        attrs = {k: f.attrs[k] for k in ("updated", "complete", "git_commit", "created") if k in f.attrs}
        return Study(path=path, job=job, theories=sorted(theories, key=lambda t: t.q1), cases=f["cases"][()],
                     E0=float(f["theory"].attrs["E0"]), nu=float(f["theory"].attrs["nu"]),
                     gamma=float(f["theory"].attrs["gamma"]), attrs=attrs)


def recompute_theory(study, q1, velocities, pressures, gamma=None):
    """Persson's theory of the study's job at q1 (1/m), recomputed at ``velocities`` (m/s) and
    ``pressures`` (Pa) with the job's quadrature and ``gamma`` (default: the job's): a
    :class:`vecontact.physics.theory.TheoryResult` (area and mu of shape (V, P)).

    gamma enters only S(q) = gamma + (1 - gamma) P(q)^2, i.e. mu; A/A0 = P(q1) does not depend on it."""
    from vecontact.cases import _theory, spectrum_for
    job = replace(study.job, theory=replace(study.job.theory, gamma=study.gamma if gamma is None else gamma))
    return _theory(job, spectrum_for(job, q1), velocities, pressures)
