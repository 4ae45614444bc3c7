"""Limits of the contact solver: elastic SNES vs PK, v -> 0 and v -> infinity, mu vs mu_geometric on a
paper-like surface, and honest reporting of non-convergence."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, Q0, PowerSpectrum, assert_contact_solution, make_fft, rms_slope, solve_full
from reference.dense import random_surface

from vecontact.physics.modulus import SLS, Elastic, HavriliakNegami

COMM = MPI.COMM_SELF
N_ROUGH = 64


def rough():
    """N = 64, q1 = 4 q0 (Nyquist = 8 q1: the paper's null band), h_rms ~ 11 nm."""
    return random_surface(N_ROUGH, L_PAPER, PowerSpectrum(Q0, 2 * Q0, 4 * Q0, 0.8, 1e-28), seed=21)


def grid_omegas(N, v):
    q = 2 * math.pi * np.fft.fftfreq(N, d=L_PAPER / N)
    return q * v


def compare_solutions(a, fa, b, fb, h, sigma0, label, tol=1e-6):
    """Same unique LCP solution up to solver tolerance: area within one point, pressures to tol sigma0,
    gaps and mean gap to tol h_rms, mu_geometric to 10 tol rms slope."""
    N = h.shape[0]
    hrms = float(np.std(h))
    assert abs(a.area - b.area) * N * N <= 1, (label, a.area, b.area)
    assert np.abs(fa["pressure"] - fb["pressure"]).max() <= tol * sigma0, (
        label, np.abs(fa["pressure"] - fb["pressure"]).max() / sigma0)
    assert np.abs(fa["gap"] - fb["gap"]).max() <= tol * hrms, (label, np.abs(fa["gap"] - fb["gap"]).max() / hrms)
    assert abs(a.mean_gap - b.mean_gap) <= tol * hrms, (label, a.mean_gap, b.mean_gap)
    assert abs(a.mu_geometric - b.mu_geometric) <= 10 * tol * rms_slope(h, L_PAPER), (
        label, a.mu_geometric, b.mu_geometric)


def test_elastic_snes_vs_pk():
    """Elastic (E = 3 MPa) rough contact at A/A0 ~ 10% and ~ 40%: SNES and Polonsky-Keer give the same
    solution to the solver tolerance (both exact for a symmetric positive definite operator)."""
    h = rough()
    fft = make_fft(COMM, N_ROUGH)
    E = Elastic(3e6, NU)
    for sigma0 in (2e3, 1e4):
        a, fa = solve_full(h, L_PAPER, E, 0.0, sigma0, fft=fft, method="snes")
        b, fb = solve_full(h, L_PAPER, E, 0.0, sigma0, fft=fft, method="pk")
        assert_contact_solution(a, fa, h, sigma0)
        assert_contact_solution(b, fb, h, sigma0)
        assert 0.03 < a.area < 0.7, a.area
        assert a.mu == 0.0 or abs(a.mu) <= 1e-14
        compare_solutions(a, fa, b, fb, h, sigma0, f"snes vs pk sigma0={sigma0}")


def test_velocity_to_zero_is_relaxed_elastic():
    """v -> 0: HN at v = 1e-25 m/s and SLS at v = 1e-15 m/s equal the elastic solution with E0.

    At these speeds |E(q_x v)/E0 - 1| < 1e-10 on the whole grid (asserted), far below the solver
    tolerance, so the solutions must coincide to solver tolerance, and mu (proportional to E'') must
    be < 1e-8 while it is > 1e-3 at v = 30 m/s for the same surface and load."""
    h = rough()
    fft = make_fft(COMM, N_ROUGH)
    sigma0 = 5e3
    ref, fref = solve_full(h, L_PAPER, Elastic(3e6, NU), 0.0, sigma0, fft=fft)
    assert_contact_solution(ref, fref, h, sigma0)
    assert 0.05 < ref.area < 0.6, ref.area
    hn = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    sls = SLS(3e6, 3e8, 1e-6, NU)
    for mod, v in ((hn, 1e-25), (sls, 1e-15)):
        E = mod(grid_omegas(N_ROUGH, v))
        assert np.abs(E / 3e6 - 1).max() < 1e-10
        res, f = solve_full(h, L_PAPER, mod, v, sigma0, fft=fft)
        assert_contact_solution(res, f, h, sigma0)
        compare_solutions(res, f, ref, fref, h, sigma0, f"v->0 {type(mod).__name__}")
        assert 0 <= res.mu < 1e-8, res.mu
    peak, fpeak = solve_full(h, L_PAPER, hn, 30.0, sigma0, fft=fft)
    assert peak.mu > 1e-3, peak.mu


class GlassyExceptStatic:
    """Real (elastic-type) modulus E = E0 at omega = 0 and Einf at omega != 0: the v -> infinity limit
    of the discrete operator. The modes with q_x = 0 (ridges along the sliding direction) are felt at
    zero frequency for any v, so on an N x N grid the limit is NOT the Einf elastic solution
    (docs/conventions.md §6 states it for the continuum, where q_x = 0 has measure zero); it is exactly this."""

    def __init__(self, E0, Einf, nu=0.5):
        self.E0, self.Einf, self.nu = float(E0), float(Einf), float(nu)

    def __call__(self, omega):
        w = np.asarray(omega, dtype=float)
        return np.where(w == 0, self.E0, self.Einf).astype(complex)


def test_velocity_to_infinity_is_glassy_elastic():
    """v -> infinity: SLS (E0 = 3 MPa, Einf = 300 MPa, tau = 1 us) at v = 1e9 m/s.

    |E(q_x v)/Einf - 1| < 1e-8 for every q_x != 0 of the grid (asserted; E''/E' ~ 1/(q v tau) < 4e-9),
    so (a) on a rough 2-D surface the solution equals the elastic one with E = Einf for q_x != 0 and
    E = E0 on the q_x = 0 column (solved by PK: the operator is real and symmetric), and (b) on a
    y-independent rough profile (no q_x = 0 modes but the mean) it equals the Einf elastic solution.
    mu -> 0 (< 1e-7) in both, while mu > 1e-3 at v = 0.1 m/s (q v tau ~ 1)."""
    h = rough()
    fft = make_fft(COMM, N_ROUGH)
    sigma0 = 5e5
    sls = SLS(3e6, 3e8, 1e-6, NU)
    v = 1e9
    omegas = grid_omegas(N_ROUGH, v)
    E = sls(omegas[omegas != 0])
    assert np.abs(E / 3e8 - 1).max() < 1e-8
    # (a) 2-D rough surface
    ref, fref = solve_full(h, L_PAPER, GlassyExceptStatic(3e6, 3e8, NU), v, sigma0, fft=fft, method="pk")
    assert_contact_solution(ref, fref, h, sigma0)
    assert 0.05 < ref.area < 0.6, ref.area
    res, f = solve_full(h, L_PAPER, sls, v, sigma0, fft=fft)
    assert_contact_solution(res, f, h, sigma0)
    compare_solutions(res, f, ref, fref, h, sigma0, "v->inf SLS (2-D)")
    assert 0 <= res.mu < 1e-7, res.mu
    # (b) y-independent profile: exactly the Einf elastic solution
    h1 = np.repeat(h[:, :1], N_ROUGH, axis=1)
    ref1, fref1 = solve_full(h1, L_PAPER, Elastic(3e8, NU), 0.0, sigma0, fft=fft)
    assert 0.05 < ref1.area < 0.8, ref1.area
    res1, f1 = solve_full(h1, L_PAPER, sls, v, sigma0, fft=fft)
    assert_contact_solution(res1, f1, h1, sigma0)
    compare_solutions(res1, f1, ref1, fref1, h1, sigma0, "v->inf SLS (1-D)")
    assert 0 <= res1.mu < 1e-7, res1.mu
    mid, _ = solve_full(h, L_PAPER, sls, 1e-1, sigma0 / 10, fft=fft)   # q v tau ~ 1 at the roll-off
    assert mid.mu > 1e-3, mid.mu


def _paper_surface(N, q1_factor, seed=1):
    from vecontact.core.surface import generate
    from vecontact.physics.spectrum import SelfAffine
    fft = make_fft(COMM, N)
    psd = SelfAffine(Q0, 4 * Q0, q1_factor * Q0, 0.8, 1.0616e-28)
    h = generate(fft, L_PAPER, psd, seed)
    return fft, fft.gather(h)


def _mu_vs_geometric(N, q1_factor, v, sigma0):
    fft, h = _paper_surface(N, q1_factor)
    hn = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    res, f = solve_full(h, L_PAPER, hn, v, sigma0, fft=fft)
    assert_contact_solution(res, f, h, sigma0)
    return res


# Paper spectrum (q0 = 2.5e5, qr = 4 q0, H = 0.8, C0 = 1.0616e-28), null band factor 8 (N = 16 q1/q0),
# HN modulus. mu (dissipation) and mu_geometric differ only by the discretisation error of the
# contact edges (docs/conventions.md §4: "agree to discretisation error"), which grows as the contact spots
# shrink: measured mu_geo/mu - 1 = -0.8% (A/A0 = 1.8%), -1.3% (1.4%), -0.3% (26%) at N = 256 and
# -0.7% (1.2%), -0.7% (2.6%) at N = 512; -2.5% at A/A0 = 0.5% (below the 1% this check is
# meant for). Tolerance 2% at A/A0 >= 1%.
MU_CASES_256 = [(1.0, 1e4), (30.0, 3e4), (0.01, 3e4)]
MU_CASES_512 = [(1.0, 1e4), (30.0, 1e5)]


def _check_mu(res):
    assert res.area >= 0.01, res.area
    assert res.mu > 5e-3, res.mu
    assert abs(res.mu_geometric / res.mu - 1) <= 0.02, (res.area, res.mu, res.mu_geometric)


@pytest.mark.parametrize("v,sigma0", MU_CASES_256)
def test_mu_vs_mu_geometric_paper_256(v, sigma0):
    _check_mu(_mu_vs_geometric(256, 16, v, sigma0))


@pytest.mark.slow
@pytest.mark.parametrize("v,sigma0", MU_CASES_512)
def test_mu_vs_mu_geometric_paper_512(v, sigma0):
    """The paper's smallest grid (q1 = 32 q0, N = 512); ~2-4 s per case."""
    _check_mu(_mu_vs_geometric(512, 32, v, sigma0))


# ----------------------------------------------------------------------- non-convergence

@pytest.mark.parametrize("method,options", [
    ("snes", {"petsc_options": {"snes_max_it": 1}}),
    ("snes", {"max_iterations": 1}),
    ("pk", {"max_iterations": 1}),
])
def test_nonconvergence_is_reported(method, options):
    """One Newton (or CG) iteration from a cold start cannot solve a ~10% contact: the result must be
    returned (no exception) with converged=False, a residual above the tolerance and a reason that
    is not "converged"."""
    h = rough()
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU) if method == "snes" else Elastic(3e6, NU)
    sigma0 = 2e4 if method == "snes" else 2e3
    res, f = solve_full(h, L_PAPER, mod, 30.0, sigma0, comm=COMM, coarse=False, method=method, **options)
    assert not bool(res.converged)
    assert res.residual > 1e-8, res.residual
    assert res.reason and str(res.reason) != "converged", res.reason
    # the same call without the limit converges (so the failure above is the limit's doing)
    ok, _ = solve_full(h, L_PAPER, mod, 30.0, sigma0, comm=COMM, coarse=False, method=method)
    assert ok.converged and ok.residual <= 1e-8, (ok.reason, ok.residual)
