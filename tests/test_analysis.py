"""Analysis of a study (vecontact.analysis): seed ensembles, curve fits and the sweep's bookkeeping,
checked against hand-computable synthetic data."""
import math
import warnings

import numpy as np
import pytest
from scipy.special import erf, erfinv

from vecontact.analysis.beyond import band_means, theory_error
from vecontact.analysis.curves import (collapse_scatter, erf_small_load_slope, fit_master_curve, interpolate,
                                       log_slope, peak, small_load_slope)
from vecontact.analysis.ensemble import seed_points, standard_error
from vecontact.analysis.sweep import core_hours
from vecontact.analysis.tables import AREA_BANDS, in_band
from vecontact.io.results import empty_row


def _case(seed, pressure, status, area, mu, q1=8e6, v=1.0, **extra):
    r = empty_row()
    r["q1"], r["seed"], r["velocity"], r["pressure"] = q1, seed, v, pressure
    r["status"], r["area"], r["mu"], r["theory_area"], r["theory_mu"] = status, area, mu, 0.2, 0.02
    for k, x in extra.items():
        r[k] = x
    return r


def test_seed_points_mean_standard_error_and_exclusions():
    rows = [_case(s, 1e4, 1, a, m) for s, a, m in ((1, 0.1, 0.01), (2, 0.2, 0.03), (3, 0.3, 0.02), (4, 0.4, 0.04))]
    rows += [_case(5, 1e4, -1, 0.9, 9.0),            # not converged: finite numbers, never averaged
             _case(6, 1e4, 0, np.nan, np.nan),        # theory only
             _case(1, 2e4, 1, 0.5, 0.05),             # a second pressure with one converged seed
             _case(2, 2e4, -1, 0.7, 0.07)]
    pts = seed_points(np.stack(rows))
    assert pts["pressure"].tolist() == [1e4, 2e4] and pts["n"].tolist() == [4, 1]
    assert pts["area"][0] == pytest.approx(0.25, rel=1e-15)
    # sample variance of (0.1, 0.2, 0.3, 0.4) = 0.05 / 3; se = sqrt(0.05 / 3) / 2
    assert pts["area_se"][0] == pytest.approx(math.sqrt(0.05 / 3) / 2, rel=1e-12)
    assert pts["mu"][0] == pytest.approx(0.025, rel=1e-14)
    assert pts["mu_se"][0] == pytest.approx(math.sqrt(((0.015 ** 2 + 0.005 ** 2) * 2) / 3) / 2, rel=1e-12)
    assert pts["area"][1] == 0.5 and math.isnan(pts["area_se"][1])   # one seed: no spread estimate
    assert pts["theory_mu"].tolist() == [0.02, 0.02]
    assert len(seed_points(np.stack(rows[4:6]))) == 0                # nothing converged: no point
    assert math.isnan(standard_error([1.0])) and standard_error([1.0, 3.0]) == pytest.approx(1.0)


def test_nan_quantity_of_one_seed_gives_nan_mean():
    rows = [_case(1, 1e4, 1, 0.1, 0.01, anisotropy_extent=1.2), _case(2, 1e4, 1, 0.1, 0.01)]
    pts = seed_points(np.stack(rows))                 # seed 2 has no anisotropy (NaN): the mean says so
    assert math.isnan(pts["anisotropy_extent"][0])


def _master_x(area, nu=0.5):
    """x with erf(sqrt(2) (1 - nu^2) x) = area: points exactly on the theory's master curve."""
    return erfinv(area) / (math.sqrt(2.0) * (1 - nu * nu))


def test_collapse_scatter_zero_on_one_curve_positive_otherwise():
    area = np.geomspace(0.005, 0.6, 12)
    x = _master_x(area)
    # several "velocities" sampling the same curve at interleaved points: one curve, scatter 0
    xs = np.concatenate([x, x * 1.05, x * 0.93])
    assert collapse_scatter(xs, erf(math.sqrt(2) * 0.75 * xs)) < 1e-12
    # a non-erf curve of the fitted family, erf(c x^1.2): still one curve
    assert collapse_scatter(xs, erf(0.9 * xs ** 1.2)) < 1e-12
    # two curves displaced by +-d in ln erfinv(A) at the same x: the least-squares fit is the middle
    # curve exactly (paired design), so the scatter is the rms of the exact residuals in ln A
    d = 0.05
    P0 = np.log(erfinv(area))
    up, down = erf(np.exp(P0 + d)), erf(np.exp(P0 - d))
    expect = np.sqrt(np.mean(np.concatenate([np.log(up / area), np.log(down / area)]) ** 2))
    assert collapse_scatter(np.concatenate([x, x]), np.concatenate([up, down])) == pytest.approx(expect, rel=1e-9)
    assert expect == pytest.approx(d, rel=0.25)                       # ~ d: nearly linear at small A
    # Fig. 4-like: the same erf in x scaled differently per curve does not collapse
    assert collapse_scatter(np.concatenate([x, x]), np.concatenate([area, erf(math.sqrt(2) * 0.75 * 2 * x)])) > 0.1
    assert math.isnan(collapse_scatter(x[:3].repeat(4), area[:3].repeat(4)))   # 3 distinct x: no fit
    with pytest.raises(ValueError):
        fit_master_curve([1.0, 2.0], [0.5, 1.0])


def test_small_load_slope_of_erf_data():
    assert erf_small_load_slope(0.5) == pytest.approx(2 * math.sqrt(2) * 0.75 / math.sqrt(math.pi), rel=1e-15)
    assert erf_small_load_slope(0.5) == pytest.approx(1.1968268, abs=1e-7)
    area = np.geomspace(0.005, 0.6, 12)
    kappa, se, n = small_load_slope(_master_x(area), area)
    assert n == int((area < 0.05).sum()) == 6
    # erf(z) = (2/sqrt(pi)) z (1 - z^2/3 + ...): at A <= 0.05, z <= 0.045, kappa low by < 7e-4
    assert kappa == pytest.approx(erf_small_load_slope(0.5), rel=1e-3) and kappa < erf_small_load_slope(0.5)
    assert se < 1e-3 * kappa
    # data A = 1.5 x exactly: kappa = 1.5 to rounding, s.e. 0
    x = np.geomspace(1e-3, 0.03, 5)
    k2, se2, _ = small_load_slope(x, 1.5 * x)
    assert k2 == pytest.approx(1.5, rel=1e-14) and se2 < 1e-14
    assert math.isnan(small_load_slope(x, 0.5 + x)[0])                 # no point below 5 %


def test_peak_of_a_non_monotonic_curve():
    area = np.geomspace(0.005, 0.6, 12)
    a_star = 0.0371                                                     # between two samples
    mu = 0.03 - 0.002 * (np.log(area) - math.log(a_star)) ** 2        # a parabola in ln A: exact vertex
    x, y, interior = peak(area, mu)
    assert interior and x == pytest.approx(a_star, rel=1e-10) and y == pytest.approx(0.03, rel=1e-12)
    x, y, interior = peak(area, 0.03 - 0.001 * np.log(area))          # monotonic falling: no peak inside
    assert not interior and x == area[0]


def test_interpolation_and_log_slope():
    x = np.array([1.0, 2.0, 8.0])
    y = 3.0 * x ** 0.5
    at = np.array([1.5, 4.0, 0.5, 9.0])
    got = interpolate(x, y, at)
    assert got[:2] == pytest.approx(3.0 * at[:2] ** 0.5, rel=1e-14)    # exact for a power law
    assert np.isnan(got[2:]).all()                                     # no extrapolation
    assert interpolate(x, np.log(x), [4.0], log_y=False)[0] == pytest.approx(math.log(4.0), rel=1e-14)
    assert log_slope(x, y, 3.0) == pytest.approx(0.5, rel=1e-14) and math.isnan(log_slope(x, y, 10.0))


def test_log_interpolation_of_a_quantity_that_reaches_zero():
    """The perimeter is 0 at full contact: the interval ending there is interpolated linearly in y (its
    ln y does not exist), the others still in ln y; no RuntimeWarning (log of 0)."""
    x = np.array([0.25, 0.5, 1.0])
    y = np.array([0.4, 0.2, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = interpolate(x, y, [math.sqrt(0.125), 0.75, 0.5, 1.0])
    assert got[0] == pytest.approx(math.sqrt(0.08), rel=1e-14)         # geometric mean: ln y linear in ln x
    t = math.log(1.5) / math.log(2.0)                                  # 0.75 on the ln x axis of [0.5, 1]
    assert got[1] == pytest.approx(0.2 * (1.0 - t), rel=1e-14)         # was 0 (exp of -inf)
    assert got[2] == pytest.approx(0.2, rel=1e-14) and got[3] == 0.0   # the samples themselves


def test_theory_error_and_bands():
    pts = np.zeros(3, dtype=[(k, "f8") for k in ("mu", "mu_se", "theory_mu", "area")])
    pts["mu"], pts["mu_se"], pts["theory_mu"] = [0.02, 0.04, 0.05], [0.001, np.nan, 0], [0.03, 0.03, 0.05]
    pts["area"] = [0.01, 0.05, 0.5]
    err, se = theory_error(pts, "mu")
    assert err == pytest.approx([0.5, -0.25, 0.0], abs=1e-15)
    assert se[0] == pytest.approx(1.5 * 0.001 / 0.02, rel=1e-14) and math.isnan(se[1])
    means, counts = band_means(pts["area"], err)
    assert counts == [1, 1, 0, 1] and np.isnan(means[2]) and means[0] == pytest.approx(0.5)
    assert in_band(np.array([1.0]), AREA_BANDS[-1])[0] and not in_band(np.array([0.02]), AREA_BANDS[0])[0]


def test_core_hours_sum_seconds_times_ranks():
    rows = [_case(1, 1e4, 1, 0.1, 0.01, seconds=1800.0, ranks=1, N=512),
            _case(2, 1e4, -1, 0.1, 0.01, seconds=900.0, ranks=4, N=2048),      # failures cost too
            _case(3, 1e4, 1, 0.1, 0.01, seconds=450.0, ranks=4, N=2048),
            _case(4, 1e4, 0, np.nan, np.nan, N=2048)]                          # theory only: no time
    got = core_hours(np.stack(rows))
    assert got == {512: (1, 0.5, [1]), 2048: (2, 1.5, [4])}


def test_table_number_formats():
    from vecontact.analysis.tables import num, percent, pm
    assert [num(3096.0), num(0.012345), num(1.94e6), num(np.int64(7)), num(np.nan)] == [
        "3100", "0.0123", "1.94e+06", "7", "—"]
    assert pm(1.2345, 0.0123) == "1.23 ± 0.012" and pm(1.2345, np.nan) == "1.23"
    assert percent(-0.1234) == "-12.3 %" and percent(0.05, 0.01) == "+5.0 ± 1.0 %"
