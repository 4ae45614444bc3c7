"""Tests of vecontact.physics.theory: Persson's theory (docs/conventions.md sections 4-6)."""
import math

import numpy as np
import pytest

from vecontact.physics.modulus import SLS, Elastic, HavriliakNegami
from vecontact.physics.spectrum import SelfAffine, Tabulated
from vecontact.physics.theory import (DEFAULT_NPHI, DEFAULT_NQ, angular_integrals, erf, mu_full_contact,
                                      persson)

Q0 = 2.5e5
C0 = 1.0616e-28
VELOCITIES = np.array([0.01, 0.1, 1.0, 10.0])
# 1 kPa .. 10 MPa spans A/A0 = 0.5 % .. 60 % for every (q1, v) of the paper with the HN compound.
PRESSURES = np.geomspace(1e3, 1e7, 41)


def paper(q1_over_q0):
    return SelfAffine(Q0, 4 * Q0, q1_over_q0 * Q0, 0.8, C0)


def compound():
    return HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)


def elastic_area(sigma0, E, nu, slope_rms):
    """A/A0 = erf(sqrt(2) sigma0 / (E* slope_rms)), E* = E / (1 - nu^2)."""
    return erf(math.sqrt(2) * (1 - nu ** 2) * np.asarray(sigma0) / (E * slope_rms))


def test_erf_matches_math_erf():
    x = np.concatenate([np.linspace(-8, 8, 40001), np.geomspace(1e-300, 1e-3, 50), [0.0, np.inf, -np.inf]])
    reference = np.vectorize(math.erf)(x)
    assert np.max(np.abs(erf(x) - reference)) < 1e-14
    small = x[(x > 0) & (x < 1e-3)]           # relative accuracy where erf ~ x (P for huge G)
    assert np.allclose(erf(small), np.vectorize(math.erf)(small), rtol=1e-14, atol=0)
    assert np.isnan(erf(np.nan)) and erf(np.zeros((2, 3))).shape == (2, 3)


def test_angular_integrals_sls_closed_form():
    # SLS, x = q v tau cos(phi), a = q v tau: |E|^2 = (E0^2 + Einf^2 x^2) / (1 + x^2) and
    # E'' = dE x / (1 + x^2), so with Int_0^{2pi} dphi / (1 + a^2 cos^2 phi) = 2 pi / sqrt(1 + a^2):
    #   Int |E|^2 dphi           = 2 pi (Einf^2 - (Einf^2 - E0^2) / sqrt(1 + a^2))
    #   Int cos(phi) E'' dphi    = 2 pi dE (1 - 1 / sqrt(1 + a^2)) / a
    E0, Einf, tau = 3e6, 3e9, 1e-6
    a = np.geomspace(1e-4, 1e4, 61)              # q v tau at v = 1 m/s
    q = a / tau
    abs2, loss = angular_integrals(SLS(E0, Einf, tau, 0.5), q, np.array([1.0]))
    root = np.sqrt(1 + a ** 2)
    assert np.allclose(abs2[0], 2 * math.pi * (Einf ** 2 - (Einf ** 2 - E0 ** 2) / root), rtol=1e-6, atol=0)
    # 1 - 1/sqrt(1 + a^2) without cancellation: a^2 / (root (1 + root)).
    assert np.allclose(loss[0], 2 * math.pi * (Einf - E0) * a / (root * (1 + root)), rtol=1e-6, atol=0)
    # Default nphi: the x^4 substitution resolves the band |cos phi| < 1/a to ~1e-7 (plain
    # Gauss-Legendre in phi would not); 1e-6 leaves margin.


@pytest.mark.parametrize("q1_over_q0", [32, 256])
def test_quadrature_converged(q1_over_q0):
    psd, modulus = paper(q1_over_q0), compound()
    base = persson(psd, modulus, VELOCITIES, PRESSURES)
    window = (base.area > 0.005) & (base.area < 0.6)
    assert window.sum() > 60 and np.all(window.any(axis=1))      # every velocity covers the window
    for factor in (2, 4):
        fine = persson(psd, modulus, VELOCITIES, PRESSURES, nq=factor * DEFAULT_NQ,
                       nphi=factor * DEFAULT_NPHI)
        for name in ("area", "mu"):
            change = np.abs(getattr(fine, name) / getattr(base, name) - 1)[window]
            assert change.max() < 1e-4, (name, factor, change.max())
        assert np.max(np.abs(fine.xi / base.xi - 1)) < 1e-4


@pytest.mark.parametrize("case", ["v=0", "elastic model"])
def test_elastic_limit(case):
    psd = paper(128)
    modulus = compound() if case == "v=0" else Elastic(3e6, 0.5)
    velocities = [0.0] if case == "v=0" else [0.01, 1.0, 10.0]
    res = persson(psd, modulus, velocities, PRESSURES)
    # Identity of the formulas: G(q1) = E*^2 slope2 / (8 sigma0^2). Gauss-Legendre in ln q is exact
    # to rounding for the power-law pieces, the closed-form slope2 is independent: 1e-6 is generous.
    expected = elastic_area(PRESSURES, 3e6, 0.5, math.sqrt(psd.slope2()))
    assert np.allclose(res.area, expected[None, :], rtol=1e-6, atol=0)
    assert np.all(res.mu == 0.0)                                   # E'' = 0: no dissipation
    # The running integral: P(q) at every node equals the closed form with q1 -> q.
    partial_slope = np.array([math.sqrt(SelfAffine(Q0, min(4 * Q0, q), q, 0.8, C0).slope2())
                              for q in res.q])
    expected_q = elastic_area(PRESSURES[:, None], 3e6, 0.5, partial_slope[None, :])
    assert np.allclose(res.P_q, expected_q[None], rtol=1e-6, atol=0)


def independent_xi(psd, modulus, v, n_q=401, n_phi=1024):
    """xi by brute force: Simpson in ln q per piece, midpoint rule in phi over [0, 2 pi)."""
    phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    total = 0.0
    for a, b in zip(psd.breakpoints[:-1], psd.breakpoints[1:]):
        s = np.linspace(math.log(a), math.log(b), n_q)
        q = np.exp(s)
        q[0], q[-1] = a, b
        s_qv = np.mean(np.abs(modulus(np.outer(q * v, np.cos(phi))) / modulus.E0) ** 2, axis=1)
        f = q ** 4 * psd(q) * s_qv
        total += (s[1] - s[0]) / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())
    return math.sqrt(2 * math.pi * total)


def test_master_curve_identity():
    psd, modulus = paper(64), compound()
    res = persson(psd, modulus, VELOCITIES, PRESSURES)
    # A/A0 = erf(sqrt(2) (1 - nu^2) sigma0 / (E0 xi)) is an identity of the formulas: rounding only.
    expected = elastic_area(PRESSURES[None, :], modulus.E0, 0.5, res.xi[:, None])
    assert np.allclose(res.area, expected, rtol=1e-6, atol=0)
    # xi itself against an independent brute-force quadrature: Simpson in ln q (h ~ 7e-3, error
    # ~h^4) and the midpoint rule in phi (the |cos phi|^(1/2) cusp of |E|^2 at phi = pi/2 limits it
    # to ~0.15 n^-1.5 ~ 5e-6 for n = 1024) are good to ~1e-5: allow 1e-4.
    for v, xi in zip(VELOCITIES, res.xi):
        assert xi == pytest.approx(independent_xi(psd, modulus, v), rel=1e-4)
    assert np.all(np.diff(res.xi) > 0)       # the rubber stiffens with speed


def lattice_mu(psd, modulus, v, sigma0, dq):
    """docs/conventions.md §4 with w = h: mu = sum_{q != 0} |q| q_x E''(q_x v) |h_q|^2 / (2 (1-nu^2) sigma0),
    |h_q|^2 = C(|q|) dq^2 on the lattice q = dq (m, n) (the origin has C = 0)."""
    n = int(math.ceil(psd.q_max / dq))
    k = np.arange(-n, n + 1) * dq
    qx, qy = np.meshgrid(k, k, indexing="ij")
    q = np.hypot(qx, qy)
    total = np.sum(q * qx * modulus(qx * v).imag * psd(q)) * dq ** 2
    return total / (2 * (1 - modulus.nu ** 2) * sigma0)


def test_full_contact_limit():
    psd, modulus = paper(32), compound()
    v, sigma0 = 1.0, 1e6
    theory = mu_full_contact(psd, modulus, [v], [sigma0])[0, 0]
    coarse = lattice_mu(psd, modulus, v, sigma0, Q0 / 8)
    fine = lattice_mu(psd, modulus, v, sigma0, Q0 / 16)
    # The lattice sum converges to the integral only as fast as the lattice resolves the jumps of
    # C(q) at |q| = q0 and q1 (a Gauss-circle-type boundary error, found ~5e-5 at dq = q0/8 and
    # ~4e-5 at q0/16, with the sign and size not monotonic). Both lattices within 2e-4 and of each other.
    assert abs(coarse - fine) < 1e-4 * theory
    assert fine == pytest.approx(theory, rel=2e-4)
    assert coarse == pytest.approx(theory, rel=2e-4)
    # persson(...) at a pressure so high that P(q1) > 0.999999 tends to the same full-contact value.
    huge = np.array([3e8, 1e9])
    res = persson(psd, modulus, VELOCITIES, huge)
    assert np.all(res.area > 0.999999)
    # mu / mu_full = <S P> with 1 - P <= 1e-6 and 1 - S <= 1e-6: within 3e-6.
    assert np.allclose(res.mu, mu_full_contact(psd, modulus, VELOCITIES, huge), rtol=3e-6, atol=0)


@pytest.mark.parametrize("modulus", [compound(), SLS(3e6, 3e9, 1e-7, 0.5)], ids=["hn", "sls"])
def test_low_and_high_speed_limits(modulus):
    psd = paper(64)
    slope = math.sqrt(psd.slope2())
    mid = persson(psd, modulus, [1.0], PRESSURES)
    # v -> 0: the rubbery plateau E0. For HN, E - E0 ~ beta (Einf - E0) (q v tau)^alpha ~ 1e-16 E0 at
    # v = 1e-30; for the SLS ~ (Einf/E0) q v tau ~ 1e-27.
    slow = persson(psd, modulus, [1e-30], PRESSURES)
    assert np.allclose(slow.area[0], elastic_area(PRESSURES, modulus.E0, 0.5, slope), rtol=1e-6, atol=0)
    # v -> infinity: the glassy plateau Einf. HN: |E - Einf| ~ Einf (q v tau)^(-alpha beta) ~ 1e-12 at
    # v = 1e50 (only the phi band |cos phi| < 1/(q v tau) sees lower frequencies).
    fast_pressures = PRESSURES * 1e3
    fast = persson(psd, modulus, [1e50], fast_pressures)
    expected_fast = elastic_area(fast_pressures, modulus.Einf, 0.5, slope)
    assert np.allclose(fast.area[0], expected_fast, rtol=1e-6, atol=0)
    # mu -> 0 at both ends, compared with mu at 1 m/s (mu ~ E''/sigma0, E'' -> 0 at both ends).
    assert np.all(slow.mu < 1e-6 * mid.mu)
    assert np.all(fast.mu * fast_pressures < 1e-6 * mid.mu * PRESSURES)
    assert np.all(mid.mu > 0)


def test_vectorisation_and_shapes():
    psd, modulus = paper(32), compound()
    velocities = np.array([0.0, 0.03, 3.0])
    pressures = np.array([2e3, 5e4, 1e6, 3e7])
    res = persson(psd, modulus, velocities, pressures, gamma=0.4)
    V, P, Q = len(velocities), len(pressures), res.q.size
    assert res.P_q.shape == res.G_q.shape == (V, P, Q)
    assert res.area.shape == res.mu.shape == (V, P) and res.xi.shape == (V,)
    assert res.slope_rms == pytest.approx(math.sqrt(psd.slope2()), rel=1e-15)
    assert np.all(np.diff(res.q) > 0) and res.q[0] > Q0 and res.q[-1] < 32 * Q0
    assert np.all(np.diff(res.P_q, axis=-1) <= 0)          # P(q) decreases with magnification
    assert np.all(res.P_q[..., -1] >= res.area)
    for i, v in enumerate(velocities):
        for j, sigma0 in enumerate(pressures):
            single = persson(psd, modulus, v, sigma0, gamma=0.4)
            assert single.area.shape == (1, 1)
            # Same arithmetic up to summation order: rounding only.
            assert single.area[0, 0] == pytest.approx(res.area[i, j], rel=1e-13)
            assert single.mu[0, 0] == pytest.approx(res.mu[i, j], rel=1e-13, abs=1e-300)
            assert np.allclose(single.P_q[0, 0], res.P_q[i, j], rtol=1e-13, atol=0)
    # gamma enters only through S = gamma + (1 - gamma) P^2.
    other = persson(psd, modulus, velocities, pressures, gamma=1.0)
    assert np.array_equal(other.area, res.area)
    assert np.all(other.mu[1:] >= res.mu[1:])                 # S = 1 >= gamma + (1 - gamma) P^2
    assert np.all(other.mu[1:, :2] > 1.1 * res.mu[1:, :2])    # partial contact: S differs by > 10 %


def test_tabulated_spectrum_gives_same_theory():
    psd = paper(32)
    q = np.unique(np.concatenate([np.geomspace(Q0, 4 * Q0, 3), np.geomspace(4 * Q0, 32 * Q0, 4)]))
    tab = Tabulated(q, psd(q))
    a = persson(psd, compound(), VELOCITIES, PRESSURES)
    b = persson(tab, compound(), VELOCITIES, PRESSURES)
    # Identical PSD; only the panel layout differs (more kinks): both converged to < 1e-7.
    assert np.allclose(a.area, b.area, rtol=1e-7, atol=0)
    assert np.allclose(a.mu, b.mu, rtol=1e-7, atol=0)
