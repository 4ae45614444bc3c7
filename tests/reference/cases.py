"""Shared problem set-ups and helpers for the solver validation tests.

Everything physical here is plain numpy; vecontact is imported lazily (inside functions) so that the
reference package stays importable and testable on its own.
"""
import math

import numpy as np

# Paper's length scale: q0 = 2 pi / L = 2.5e5 1/m (docs/conventions.md §2).
Q0 = 2.5e5
L_PAPER = 2.0 * math.pi / Q0
E_RUBBER = 3.0e6
NU = 0.5


class ConstModulus:
    """Minimal elastic modulus callable for the reference's own tests (no vecontact import)."""

    def __init__(self, E, nu=0.5):
        self.E0 = self.Einf = float(E)
        self.nu = float(nu)

    def __call__(self, omega):
        return np.full(np.shape(omega), self.E0, dtype=complex)


class HNModulus:
    """Havriliak-Negami modulus written out independently (docs/conventions.md §3) for the reference tests."""

    def __init__(self, E0=3e6, Einf=3e9, alpha=0.5, beta=0.5, tau=1e-10, nu=0.5):
        self.E0, self.Einf, self.alpha, self.beta, self.tau, self.nu = E0, Einf, alpha, beta, tau, nu

    def __call__(self, omega):
        w = np.asarray(omega, dtype=float)
        z = (np.abs(w) * self.tau) ** self.alpha * np.exp(0.5j * math.pi * self.alpha)
        E = self.Einf + (self.E0 - self.Einf) / (1.0 + z) ** self.beta
        return np.where(w < 0, np.conj(E), E)


class PowerSpectrum:
    """Self-affine spectrum with roll-off, written out independently (docs/conventions.md §2)."""

    def __init__(self, q0, qr, q1, hurst, C0):
        self.q0, self.qr, self.q1, self.hurst, self.C0 = q0, qr, q1, hurst, C0

    def __call__(self, q):
        q = np.asarray(q, dtype=float)
        out = np.where(q <= self.qr, self.C0, self.C0 * (np.maximum(q, self.qr) / self.qr) ** (-2 * (1 + self.hurst)))
        return np.where((q >= self.q0 * (1 - 1e-12)) & (q <= self.q1 * (1 + 1e-12)), out, 0.0)


def small_spectrum(N, L=L_PAPER, C0=1e-28):
    """Spectrum for dense comparisons: q0 = 2 pi / L, qr = 2 q0, q1 = N/6 q0, H = 0.8."""
    q0 = 2.0 * math.pi / L
    return PowerSpectrum(q0, 2.0 * q0, N / 6.0 * q0, 0.8, C0)


def rms_slope(h, L):
    """Full 2-D rms slope of an N x N field by spectral differentiation."""
    N = h.shape[0]
    q = 2.0 * math.pi * np.fft.fftfreq(N, d=L / N)
    qx, qy = np.meshgrid(q, q, indexing="ij")
    hq = np.fft.fft2(h) / N ** 2
    return float(np.sqrt(np.sum((qx ** 2 + qy ** 2) * np.abs(hq) ** 2)))


# ----------------------------------------------------------------------------- solver glue

def make_fft(comm, N):
    from vecontact.core.pfft import SlabFFT
    return SlabFFT(comm, N)


def solve_full(h_full, L, modulus, velocity, sigma0, comm=None, fft=None, **kw):
    """Run vecontact.solver.solve_contact on the full N x N height field h_full (every rank holds it).

    Returns (res, fields) where fields = dict(pressure, gap, displacement) gathered to full arrays
    on every rank (None for fields not stored).
    """
    from mpi4py import MPI
    from vecontact.solver import solve_contact

    comm = comm if comm is not None else MPI.COMM_SELF
    N = h_full.shape[0]
    fft = fft if fft is not None else make_fft(comm, N)
    h_local = np.ascontiguousarray(h_full[fft.row_start:fft.row_stop, :], dtype=float)
    res = solve_contact(fft, L, h_local, modulus, velocity, sigma0, **kw)
    fields = {}
    for name in ("pressure", "gap", "displacement"):
        local = getattr(res, name, None)
        if local is None:
            fields[name] = None
            continue
        full = fft.gather(np.ascontiguousarray(local, dtype=float))
        fields[name] = comm.bcast(full if comm.rank == 0 else None, root=0)
    return res, fields


def assert_contact_solution(res, fields, h, sigma0, tol_p=1e-6, tol_g=1e-6):
    """Generic checks every returned solution must pass (up to solver tolerance).

    * p >= 0 everywhere (exactly: an LCP solution has no tensile pressure);
    * mean(p) = sigma0 to tol_p (relative);
    * g >= -tol_g h_rms; contact (p > 0) implies |g| <= tol_g h_rms; and
      p g <= tol_p sigma0 * tol_g-scaled (complementarity);
    * reported area equals the fraction of p > 0 in the returned field;
    * reported mean gap equals mean of the returned gap field.
    """
    p = fields["pressure"]
    g = fields["gap"]
    hrms = float(np.std(h)) or 1.0
    assert res.converged, f"solver did not converge: reason={res.reason} residual={res.residual}"
    assert np.all(p >= 0.0), f"negative pressure {p.min() / sigma0:.3e} sigma0"
    assert abs(p.mean() / sigma0 - 1.0) <= tol_p, f"load balance {p.mean() / sigma0 - 1.0:.3e}"
    assert g.min() >= -tol_g * hrms, f"penetration {g.min() / hrms:.3e} h_rms"
    contact = p > 0
    if contact.any():
        assert np.abs(g[contact]).max() <= tol_g * hrms, (
            f"gap in contact {np.abs(g[contact]).max() / hrms:.3e} h_rms")
    assert res.area == np.count_nonzero(contact) / p.size, (res.area, np.count_nonzero(contact) / p.size)
    assert abs(res.mean_gap - g.mean()) <= 1e-12 * hrms + 1e-9 * abs(g.mean()), (res.mean_gap, g.mean())


#: PETSc options that let paper_contact_solve's contact-set steps carry directions: its grid's modulus
#: range at 10 m/s (82 at 256^2) is under carry_modulus_min's default (100).  The edge term keeps
#: edge_window on every grid: with edge_window_large on the coarse grids (their sets pass
#: edge_large_area at a range under edge_large_modulus_max) the carry's coarse answers, a little
#: different, move one point of the fine grid's first set, and the tests compare the paths with and
#: without the carry step by step
CARRY_OPEN = {"vc_carry_modulus_min": "50", "vc_edge_large_area": "2"}


def paper_case(N=256):
    """The seed-1 paper surface at N (q1 = N/16 q0) on one rank and the HN compound: (fft, h, hn)."""
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    from vecontact.physics.modulus import HavriliakNegami
    from vecontact.physics.spectrum import SelfAffine
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    h = generate(fft, L_PAPER, SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28), 1)
    return fft, h, HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)


def paper_contact_solve(options, N=256):
    """solve_contact on paper_case's surface, HN at 10 m/s, 1.1e5 Pa (A/A0 ~ 7.6 % at 256²:
    contact-set steps), tolerance 1e-8, with the PETSc ``options``: (result, whole-grid contact set)."""
    from vecontact.solver import solve_contact
    fft, h, hn = paper_case(N)
    r = solve_contact(fft, L_PAPER, h, hn, 10.0, 1.1e5, tolerance=1e-8, store=("pressure",),
                      petsc_options=options)
    return r, fft.gather(r.pressure > 0)
