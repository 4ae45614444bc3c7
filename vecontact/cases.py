"""The sweep: expand a resolved job into cases and the theory that goes with them.

A case is one (q1, seed, velocity, pressure). Persson's theory is computed for every case,
whether or not the numerical solver runs, and for dense curves used by the figures.
Units: q in 1/m, C in m^4, velocity in m/s, pressure in Pa.
"""
from dataclasses import dataclass

import numpy as np

from vecontact.jobtypes import AreaRange
from vecontact.physics import spectrum as spectra
from vecontact.physics.theory import erf, persson
from vecontact.rows import theory_row

CURVE_POINTS = 80
# erfinv range of the dense theory curves: A/A0 from about 1e-3 to 0.95
CURVE_X = np.geomspace(1e-3, 1.4, CURVE_POINTS)


@dataclass(frozen=True, order=True)
class Case:
    q1: float
    seed: int
    velocity: float
    pressure: float

    @property
    def key(self):
        return (self.q1, self.seed, self.velocity, self.pressure)

    @property
    def name(self):
        return f"q1_{self.q1:.6e}_seed_{self.seed}_v_{self.velocity:.6e}_p_{self.pressure:.6e}"


def spectrum_for(job, q1):
    """The self-affine spectrum of the job at cut-off q1 (hrms normalises the largest q1)."""
    s = job.surface
    if s.C0 is not None:
        return spectra.SelfAffine(s.q0, s.qr, q1, s.hurst, s.C0)
    ref = spectra.SelfAffine.from_hrms(s.q0, s.qr, max(s.q1), s.hurst, s.hrms)
    return spectra.SelfAffine(s.q0, s.qr, q1, s.hurst, ref.C0)


def _theory(job, psd, velocities, pressures):
    t = job.theory
    kw = {k: n for k, n in (("nq", t.nq), ("nphi", t.nphi)) if n}
    return persson(psd, job.material.modulus(), np.asarray(velocities, float),
                   np.asarray(pressures, float), gamma=t.gamma, **kw)


def _pressure_list(job, psd, velocity):
    """Pressures of the sweep at one (q1, v): explicit, or chosen from the theory's area range."""
    p = job.sweep.pressure
    if not isinstance(p, AreaRange):
        return list(p)
    # area targets: invert the master curve A/A0 = erf(sqrt(2)(1-nu^2) sigma0/(E0 xi)) exactly
    mat = job.material
    xi = float(_theory(job, psd, [velocity], [1.0]).xi[0])
    x = _erfinv(np.geomspace(p.area_min, p.area_max, p.num))
    sig = x * mat.modulus().E0 * xi / (np.sqrt(2.0) * (1.0 - mat.nu ** 2))
    return [float(f"{s:.6e}") for s in sig]


def _erfinv(y):
    """Inverse error function on (0, 1) by Newton iteration on the package's erf."""
    y = np.asarray(y, float)
    x = np.sqrt(-np.log1p(-y * y)) * np.sign(y)  # rough start, then Newton
    for _ in range(50):
        dx = (erf(x) - y) / (2.0 / np.sqrt(np.pi) * np.exp(-x * x))
        x = x - dx
        if np.max(np.abs(dx)) < 1e-15:
            break
    return x


def expand(job, psds):
    """All cases of the job, sorted. ``psds`` maps q1 -> spectrum (callable C(q))."""
    cases = []
    for q1, psd in psds.items():
        for seed in job.surface.realisations(q1):
            for v in job.sweep.velocity:
                for p in _pressure_list(job, psd, v):
                    cases.append(Case(float(q1), int(seed), float(v), float(p)))
    return sorted(cases)


def r_pressures(cases, velocity):
    """The sorted pressures (Pa) of the cases at one velocity."""
    return sorted({c.pressure for c in cases if c.velocity == velocity})


def theory(job, psds, cases):
    """Theory rows for every case and the /theory and /spectrum groups of the results file.

    Returns (rows, groups): rows maps case key -> results row with the theory columns filled.
    """
    rows, theory_group, spectrum_group = {}, {}, {}
    nu = job.material.nu
    E0 = job.material.modulus().E0
    velocities = job.sweep.velocity
    for i, (q1, psd) in enumerate(sorted(psds.items())):
        mine = [c for c in cases if c.q1 == q1]
        per_v = [_theory(job, psd, [v], r_pressures(mine, v)) for v in velocities]
        xi = np.array([r.xi[0] for r in per_v])
        for c in mine:
            r = per_v[velocities.index(c.velocity)]
            k = r_pressures(mine, c.velocity).index(c.pressure)
            rows[c.key] = theory_row(c.key, r.area[0, k], r.mu[0, k], r.xi[0], r.slope_rms)
        # dense curves along the master curve for the figures
        curve_p = CURVE_X[None, :] * E0 * xi[:, None] / (np.sqrt(2.0) * (1 - nu ** 2))
        curves = [_theory(job, psd, [v], curve_p[k]) for k, v in enumerate(velocities)]
        theory_group[f"q1_{i}"] = {
            "@q1": q1, "@slope_rms": float(per_v[0].slope_rms), "@hrms": float(psd.hrms()),
            "velocity": np.asarray(velocities), "xi": xi, "q": np.append(per_v[0].q, psd.q_max),
            "pressure": np.array([r_pressures(mine, v) for v in velocities]),
            # quadrature nodes, closed by the end point P(q1) = A/A0
            "P_q": np.concatenate([np.concatenate([r.P_q, r.area[..., None]], axis=-1) for r in per_v]),
            "area": np.concatenate([r.area for r in per_v]),
            "mu": np.concatenate([r.mu for r in per_v]),
            "curves": {"pressure": curve_p, "area": np.concatenate([r.area for r in curves]),
                       "mu": np.concatenate([r.mu for r in curves])},
        }
        qs = np.geomspace(psd.q_min, psd.q_max, 400)
        spectrum_group[f"q1_{i}"] = {"@q1": q1, "q": qs, "C": psd(qs)}
    attrs_t = {"gamma": job.theory.gamma, "E0": E0, "nu": nu,
               "units": "q: 1/m; pressure: Pa; velocity: m/s; P_q, area, mu, xi: dimensionless",
               "layout": "q1_<i>/pressure[velocity, k], P_q[velocity, k, q], area/mu[velocity, k]; "
                         "curves/*[velocity, j] (dense, for figures)"}
    groups = {"theory": (theory_group, attrs_t),
              "spectrum": (spectrum_group, {"units": "q: 1/m; C: m^4 (Persson's convention)"})}
    return rows, groups
