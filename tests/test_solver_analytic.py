"""Contact solver vs closed-form results (docs/conventions.md §6): Westergaard, JGH 2-D sinusoid, full contact.

Tolerances are the discretisation errors of the exact discrete problem (measured with the dense
reference, tests/reference), not of the solver: the solver itself is checked to ~1e-6 against the
exact discrete solution wherever one is available.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from reference import analytic as an
from reference.cases import L_PAPER, NU, assert_contact_solution, make_fft, rms_slope, solve_full
from reference.dense import dense_solve_1d, random_surface
from reference.cases import PowerSpectrum

from vecontact.physics.modulus import SLS, Elastic, HavriliakNegami

E0 = 3e6
COMM = MPI.COMM_SELF


def hn():
    return HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)


# --------------------------------------------------------------------------- Westergaard

WEST_N = 128
WEST_D = 1e-8          # 10 nm amplitude, lambda = L = 25 um (paper-like scales, heights in metres)


@pytest.fixture(scope="module")
def westergaard_refs():
    """Exact discrete 1-D solutions (dense reference) for the three loads."""
    x = np.arange(WEST_N) * L_PAPER / WEST_N
    hx = WEST_D * np.cos(2 * math.pi * x / L_PAPER)
    ps = an.westergaard_pstar(E0, NU, WEST_D, L_PAPER)
    return hx, ps, {r: dense_solve_1d(hx, L_PAPER, Elastic(E0, NU), 0.0, r * ps) for r in (0.1, 0.3, 0.7)}


@pytest.mark.parametrize("method", ["snes", "pk"])
def test_westergaard(method, westergaard_refs):
    """1-D sinusoid h = D cos(2 pi x / L), constant along y, elastic, N = 128, r = pbar/p* = 0.1, 0.3, 0.7.

    Tolerances vs the continuum (docs/conventions.md §6): A/A0 within 2/N (the contact edge falls between
    grid points: one point per edge; the exact discrete solution is within 0.8/N), p_max within 0.5%
    (exact discrete: <= 3e-5), mean gap within 0.1% (exact discrete: <= 5.7e-4 at r = 0.7).
    Against the exact discrete solution (dense 1-D reference, unique LCP solution): same contact
    set, pressures to 1e-6 sigma0, gaps to 1e-6 h_rms, and no y-dependence.
    """
    hx, ps, refs = westergaard_refs
    N = WEST_N
    h = hx[:, None] * np.ones((1, N))
    hrms = float(np.std(h))
    fft = make_fft(COMM, N)
    for r, ref in refs.items():
        sigma0 = r * ps
        res, f = solve_full(h, L_PAPER, Elastic(E0, NU), 0.0, sigma0, fft=fft, method=method)
        assert_contact_solution(res, f, h, sigma0)
        A = an.westergaard_area(r)
        assert abs(res.area - A) <= 2.0 / N, (r, res.area, A)
        pm = an.westergaard_pmax(sigma0, ps)
        assert abs(f["pressure"].max() - pm) <= 5e-3 * pm, (r, f["pressure"].max() / pm - 1)
        mg = an.westergaard_mean_gap(WEST_D, r)
        assert abs(res.mean_gap - mg) <= 1e-3 * mg, (r, res.mean_gap / mg - 1)
        # exact discrete solution
        assert res.area == ref.area, (r, res.area, ref.area)
        dp = np.abs(f["pressure"] - ref.pressure[:, None]).max() / sigma0
        assert dp <= 1e-6, (r, dp)
        dg = np.abs(f["gap"] - ref.gap[:, None]).max() / hrms
        assert dg <= 1e-6, (r, dg)
        assert abs(res.mean_gap - ref.mean_gap) <= 1e-6 * hrms
        assert abs(res.mu) <= 1e-14          # elastic: no dissipation
        assert abs(res.mu_geometric - ref.mu_geometric) <= 1e-6 * rms_slope(h, L_PAPER)


def test_viscoelastic_1d_sinusoid_exact():
    """Partial contact of a viscoelastic solid on a 1-D two-harmonic profile (N = 128) vs the exact
    discrete 1-D dense solution: a large-N check of the non-symmetric operator, the sign of E''
    and the friction estimates (mu to 1e-5 relative, pressures to 1e-6 sigma0)."""
    N = 128
    x = np.arange(N) * L_PAPER / N
    k = 2 * math.pi / L_PAPER
    hx = 1e-8 * (np.cos(k * x) + 0.4 * np.cos(3 * k * x + 1.0))
    h = hx[:, None] * np.ones((1, N))
    mod = hn()
    for v, sigma0 in ((30.0, 2e4), (1.0, 1e4)):
        ref = dense_solve_1d(hx, L_PAPER, mod, v, sigma0)
        assert 0.1 < ref.area < 0.6 and ref.mu > 1e-3
        res, f = solve_full(h, L_PAPER, mod, v, sigma0, comm=COMM)
        assert_contact_solution(res, f, h, sigma0)
        assert abs(res.area - ref.area) <= 1.0 / N, (v, res.area, ref.area)
        assert np.abs(f["pressure"] - ref.pressure[:, None]).max() <= 1e-6 * sigma0
        assert abs(res.mu / ref.mu - 1) <= 1e-5, (v, res.mu, ref.mu, ref.mu_literal)
        assert abs(res.mu_geometric / ref.mu_geometric - 1) <= 1e-5, (v, res.mu_geometric, ref.mu_geometric)
        assert abs(res.mean_gap - ref.mean_gap) <= 1e-6 * float(np.std(hx))


# ---------------------------------------------------------------- JGH 2-D sinusoid (elastic)

JGH_N = 256
JGH_D = 1e-8


def _jgh_area(fft, r):
    N = JGH_N
    x = np.arange(N) * L_PAPER / N
    c = np.cos(2 * math.pi * x / L_PAPER)
    h = JGH_D * c[:, None] * c[None, :]
    ps = an.jgh_pstar(E0, NU, JGH_D, L_PAPER)
    res, f = solve_full(h, L_PAPER, Elastic(E0, NU), 0.0, r * ps, fft=fft)
    assert_contact_solution(res, f, h, r * ps)
    # the solution has the symmetries of h: p(x, y) = p(y, x) = p(-x, y)
    p = f["pressure"]
    assert np.abs(p - p.T).max() <= 1e-6 * r * ps
    assert np.abs(p - np.roll(np.flip(p, 0), 1, 0)).max() <= 1e-6 * r * ps
    return res.area


def test_jgh_low_load():
    """Low load: A/A0 -> 0.7616 (pbar/p*)^(2/3) (two Hertz contacts per cell).

    N = 256, lambda = L, r = 0.005 and 0.01 (A/A0 = 2.3%, 3.7%: contact radius 15-19 dx).
    Exact discrete solutions (independent numpy Polonsky-Keer, checked against the dense
    reference) give ratios 1.032 and 1.037: the finite-load correction to Hertz is positive and
    grows with r (1.056 at r = 0.02, 1.11 at 0.05) and the edge discretisation adds +-1%.
    Tolerance: ratio in [1, 1.06].
    """
    fft = make_fft(COMM, JGH_N)
    for r in (0.005, 0.01):
        A = _jgh_area(fft, r)
        ratio = A / an.jgh_area_low(r)
        assert 1.0 <= ratio <= 1.06, (r, A, ratio)


def test_jgh_near_full_contact():
    """Near full contact: 1 - A/A0 -> (3/(2 pi)) (1 - pbar/p*).

    N = 256, r = 0.9 and 0.95 (non-contact fraction 4.8% and 2.4%, two holes per cell of radius
    ~22 and 16 dx). Exact discrete values of (1 - A)/(3 (1 - r)/(2 pi)): 1.023 and 1.004 (the
    correction is O(1 - r)); tolerance 5% on the non-contact fraction.
    """
    fft = make_fft(COMM, JGH_N)
    for r in (0.9, 0.95):
        A = _jgh_area(fft, r)
        ratio = (1 - A) / (1 - an.jgh_area_high(r))
        assert abs(ratio - 1) <= 0.05, (r, A, ratio)


# ------------------------------------------------------------------------- full contact

def _moduli():
    # SLS with its loss peak near omega = 1/(tau sqrt(Einf/E0)) = 3.2e7 rad/s, i.e. v ~ 40 m/s for k = 3 q0
    return {"hn": hn(), "sls": SLS(3e6, 3e7, 1e-8, 0.5)}


@pytest.mark.parametrize("model", ["hn", "sls"])
def test_full_contact_cosine(model):
    """h = h0 cos(k x), k = 3 q_L, N = 32, sigma0 = 2 |M_k| h0 (full contact): for every v
    mu = k^2 h0^2 E''(kv) / (4 (1 - nu^2) sigma0) to 1e-6 relative (mu and mu_geometric), the
    pressure is sigma0 + |M_k| h0 cos(kx + delta) with delta = arg E(kv): phase of the first
    harmonic to 1e-6 rad, amplitude to 1e-6 relative, all other harmonics < 1e-8 sigma0.
    These are exact for the discrete problem (a single band-limited mode), so only the solver
    tolerance enters."""
    mod = _moduli()[model]
    N, h0, m = 32, 1e-8, 3
    k = 2 * math.pi * m / L_PAPER
    x = np.arange(N) * L_PAPER / N
    h = h0 * np.cos(k * x)[:, None] * np.ones((1, N))
    fft = make_fft(COMM, N)
    # velocities from far below to far above the loss peak (k v tau ~ 1e-4 .. 1e2 for HN)
    for v in (1e-3, 1.0, 36.0, 300.0, 1e4):
        Ek = complex(mod(np.array([k * v]))[0])
        Mk = k * abs(Ek) / (2 * (1 - NU ** 2))
        sigma0 = 2.0 * Mk * h0
        res, f = solve_full(h, L_PAPER, mod, v, sigma0, fft=fft)
        assert_contact_solution(res, f, h, sigma0)
        assert res.area == 1.0
        mu = an.cosine_mu(k, h0, mod, NU, v, sigma0)
        assert mu > 0
        assert abs(res.mu / mu - 1) <= 1e-6, (v, res.mu, mu)
        assert abs(res.mu_geometric / mu - 1) <= 1e-6, (v, res.mu_geometric, mu)
        P = np.fft.fft2(f["pressure"]) / N ** 2
        delta = an.cosine_phase(k, mod, v)
        assert abs(np.angle(P[m, 0]) - delta) <= 1e-6, (v, np.angle(P[m, 0]), delta)
        assert abs(2 * abs(P[m, 0]) / (Mk * h0) - 1) <= 1e-6
        assert abs(P[0, 0] / sigma0 - 1) <= 1e-8
        P[m, 0] = P[-m, 0] = P[0, 0] = 0
        assert np.abs(P).max() <= 1e-8 * sigma0
        assert abs(res.mean_gap) <= 1e-6 * h0


@pytest.mark.parametrize("model,v", [("hn", 0.3), ("hn", 30.0), ("sls", 40.0)])
def test_full_contact_random(model, v):
    """Random rough surface (N = 64, q1 = 4 q_L: null band factor 8) in full contact: pressure =
    sigma0 + M h and mu = section-4 formula with w = h, both to 1e-6; mu_geometric equals mu
    to 1e-6 (an identity in full contact)."""
    mod = _moduli()[model]
    N = 64
    q0 = 2 * math.pi / L_PAPER
    h = random_surface(N, L_PAPER, PowerSpectrum(q0, 2 * q0, 4 * q0, 0.8, 1e-28), seed=11)
    p_el = an.full_contact_pressure(h, L_PAPER, mod, NU, v, 0.0)
    sigma0 = 1.3 * (-p_el.min())
    res, f = solve_full(h, L_PAPER, mod, v, sigma0, comm=COMM)
    assert_contact_solution(res, f, h, sigma0)
    assert res.area == 1.0
    assert np.abs(f["pressure"] - (sigma0 + p_el)).max() <= 1e-6 * sigma0
    mu = an.full_contact_mu(h, L_PAPER, mod, NU, v, sigma0)
    assert mu > 1e-4
    assert abs(res.mu / mu - 1) <= 1e-6, (res.mu, mu)
    assert abs(res.mu_geometric / mu - 1) <= 1e-6, (res.mu_geometric, mu)
