"""Tests of vecontact.physics.spectrum (docs/conventions.md §2)."""
import math

import numpy as np
import pytest

from vecontact.physics.spectrum import SelfAffine, Tabulated

Q0 = 2.5e5
C0 = 1.0616e-28


def paper(q1_over_q0, hurst=0.8):
    return SelfAffine(Q0, 4 * Q0, q1_over_q0 * Q0, hurst, C0)


def simpson_log_moment(psd, n, points_per_piece=4001):
    """2 pi Int q^(n+1) C dq by composite Simpson in ln q, piece by piece between the kinks."""
    total = 0.0
    for a, b in zip(psd.breakpoints[:-1], psd.breakpoints[1:]):
        s = np.linspace(math.log(a), math.log(b), points_per_piece)
        q = np.exp(s)
        q[0], q[-1] = a, b                            # exact ends: C is 0 just outside the support
        f = q ** (n + 2) * psd(q)                     # dq = q ds
        h = s[1] - s[0]
        total += h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())
    return 2 * math.pi * total


def test_paper_rms_heights():
    # docs/conventions.md §2: 27.0 nm at q1 = 256 q0 and 26.7 nm at q1 = 32 q0 (printed digits).
    assert round(paper(256).hrms() * 1e9, 1) == 27.0
    assert round(paper(32).hrms() * 1e9, 1) == 26.7


@pytest.mark.parametrize("spec", [
    (Q0, 4 * Q0, 256 * Q0, 0.8),
    (Q0, 4 * Q0, 32 * Q0, 0.3),
    (Q0, Q0, 64 * Q0, 0.8),          # no roll-off
    (Q0, 4 * Q0, 64 * Q0, 1.0),      # slope2 integrand ~ q^-1: the logarithmic branch
    (Q0, 4 * Q0, 4 * Q0, 0.8),       # roll-off only
])
@pytest.mark.parametrize("n", [0, 1, 2, 4])
def test_closed_form_moments_vs_quadrature(spec, n):
    psd = SelfAffine(*spec, C0)
    # Simpson in ln q on smooth pieces with h ~ 1e-3: relative error ~ h^4 < 1e-11; allow 1e-9.
    assert psd.moment(n) == pytest.approx(simpson_log_moment(psd, n), rel=1e-9)
    assert psd.hrms2() == psd.moment(0) and psd.slope2() == psd.moment(2)
    assert psd.hrms() == pytest.approx(math.sqrt(psd.moment(0)), rel=1e-15)


def test_values_support_and_breakpoints():
    psd = paper(64)
    qr, q1 = 4 * Q0, 64 * Q0
    q = np.array([0.5 * Q0, Q0, 2 * Q0, qr, 2 * qr, q1, 1.0001 * q1])
    expected = [0.0, C0, C0, C0, C0 * 2 ** -3.6, C0 * 16 ** -3.6, 0.0]
    assert np.allclose(psd(q), expected, rtol=1e-14, atol=0)
    assert psd(q.reshape(7, 1)).shape == (7, 1)
    assert psd.breakpoints == [Q0, qr, q1]
    assert (psd.q_min, psd.q_max) == (Q0, q1)
    assert SelfAffine(Q0, Q0, q1, 0.8, C0).breakpoints == [Q0, q1]


def test_from_hrms():
    psd = SelfAffine.from_hrms(Q0, 4 * Q0, 256 * Q0, 0.8, 27.0003547735e-9)
    assert psd.C0 == pytest.approx(C0, rel=1e-9)
    assert psd.hrms() == pytest.approx(27.0003547735e-9, rel=1e-14)


def test_tabulated_reproduces_power_law_pieces():
    # Sampling the self-affine PSD at its kinks and in between: the log-log interpolant IS the
    # self-affine PSD, so values and (exact piecewise power-law) moments must agree to rounding.
    psd = paper(128)
    q = np.unique(np.concatenate([np.geomspace(Q0, 4 * Q0, 5), np.geomspace(4 * Q0, 128 * Q0, 9)]))
    tab = Tabulated(q, psd(q))
    probe = np.geomspace(0.9 * Q0, 130 * Q0, 301)
    assert np.allclose(tab(probe), psd(probe), rtol=1e-12, atol=0)
    for n in (0, 2, 3):
        assert tab.moment(n) == pytest.approx(psd.moment(n), rel=1e-12)
    assert tab.breakpoints == list(q) and (tab.q_min, tab.q_max) == (q[0], q[-1])


def test_tabulated_generic_moments():
    rng = np.random.default_rng(1)
    q = np.geomspace(1e5, 1e8, 40)
    C = 1e-28 * (q / 1e5) ** -3.2 * np.exp(0.3 * rng.standard_normal(q.size))
    tab = Tabulated(q, C)
    assert (tab.hrms2(), tab.slope2()) == (tab.moment(0), tab.moment(2))
    for n in (0, 2):
        # Simpson on each power-law piece (4001 points): relative error < 1e-10.
        assert tab.moment(n) == pytest.approx(simpson_log_moment(tab, n), rel=1e-9)


def test_tabulated_rejects_bad_samples():
    with pytest.raises(ValueError):
        Tabulated([1.0, 1.0], [1.0, 2.0])
    with pytest.raises(ValueError):
        Tabulated([1.0, 2.0], [1.0, 0.0])
