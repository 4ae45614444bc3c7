"""Numbers read off curves: master-curve collapse, small-load slope, peaks and log-log interpolation.

All fits are in logarithms (natural log), where the contact-area curves are smooth and relative errors
are what matters:

* collapse: one curve A = erf(exp(P(ln x))) through all the points (every q1 and v), P a least-squares
  polynomial of degree :data:`COLLAPSE_DEGREE` fitted to ln erfinv(A) against ln x. The family holds
  the theory's master curve erf(sqrt(2) (1 - nu^2) x) exactly (P linear, slope 1) and smooth departures
  from it. The scatter is the rms of ln A - ln(fitted A) (roughly the rms relative deviation from one
  curve; 0 for points on one curve of the family). Requires 0 < A < 1.
* small-load slope: A ~ kappa x at small x; kappa = exp(mean ln(A / x)) over the points with
  A < ``area_max`` (the least-squares fit of ln A = ln kappa + ln x, unit slope imposed).
* a peak of y(x): the largest point; when it is interior, the vertex of the parabola through it and its
  two neighbours in (ln x, y) locates it between the samples.
"""
import math

import numpy as np
from scipy.special import erf, erfinv

#: Degree of the polynomial in ln x fitted to ln erfinv(A) for the master curve (4 parameters; a curve
#: of the study has 12 points, a collapse tens).
COLLAPSE_DEGREE = 3
#: Points with A/A0 below this enter the small-load slope (erf's curvature: kappa low by < 0.1 %).
SMALL_LOAD_AREA = 0.05


def fit_master_curve(x, area, degree=COLLAPSE_DEGREE):
    """Least-squares polynomial P (numpy.polynomial.Polynomial) with ln erfinv(A) ~ P(ln x)."""
    area = np.asarray(area, float)
    if np.any((area <= 0) | (area >= 1)):
        raise ValueError("the master-curve fit needs 0 < A/A0 < 1")
    return np.polynomial.Polynomial.fit(np.log(x), np.log(erfinv(area)), degree)


def enough_abscissas(x, degree=COLLAPSE_DEGREE):
    """More distinct x (to 1e-9 relative) than the degree + 1 parameters of the master-curve fit."""
    u = np.unique(np.round(np.log(np.asarray(x, float)), 9))
    return u.size > degree + 1


def master_curve(fit, x):
    """A/A0 on the fitted curve: erf(exp(P(ln x))) (exp overflowing to inf gives erf = 1, full contact)."""
    with np.errstate(over="ignore"):
        return erf(np.exp(fit(np.log(np.asarray(x, float)))))


def collapse_scatter(x, area, degree=COLLAPSE_DEGREE):
    """rms of ln A - ln(fitted A) around the curve :func:`fit_master_curve` through all the points;
    NaN unless there are more distinct abscissas than the fit's degree + 1 parameters (else the
    polynomial interpolates and the scatter means nothing)."""
    x, area = np.asarray(x, float), np.asarray(area, float)
    if not enough_abscissas(x, degree):
        return np.nan
    residual = np.log(area) - np.log(master_curve(fit_master_curve(x, area, degree), x))
    return float(np.sqrt(np.mean(residual ** 2)))


def small_load_slope(x, y, area_max=SMALL_LOAD_AREA):
    """kappa in y ~ kappa x from the points with y < area_max.

    Returns (kappa, standard error, points used): kappa = exp(mean ln(y/x)); its standard error is
    kappa times the standard error of that mean (NaN for fewer than 2 points; kappa NaN for none)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    small = y < area_max
    ratio = np.log(y[small] / x[small])
    if ratio.size == 0:
        return np.nan, np.nan, 0
    kappa = math.exp(ratio.mean())
    se = kappa * ratio.std(ddof=1) / math.sqrt(ratio.size) if ratio.size >= 2 else np.nan
    return kappa, se, int(ratio.size)


def erf_small_load_slope(nu):
    """The theory's small-load slope: A/A0 = erf(sqrt(2) (1 - nu^2) x) ~ (2 / sqrt(pi)) sqrt(2)
    (1 - nu^2) x, so kappa = 2 sqrt(2) (1 - nu^2) / sqrt(pi) (1.197 for nu = 0.5)."""
    return 2.0 * math.sqrt(2.0) * (1.0 - nu ** 2) / math.sqrt(math.pi)


def peak(x, y):
    """Location of the maximum of y(x), x > 0 rising.

    Returns (x_peak, y_peak, interior): the largest sample, refined when it is interior by the vertex of
    the parabola through it and its neighbours in (ln x, y); ``interior`` is False when the largest
    sample is the first or the last (y rises or falls monotonically over the range: no peak inside)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    i = int(np.argmax(y))
    if i == 0 or i == len(y) - 1:
        return float(x[i]), float(y[i]), False
    u = np.log(x[i - 1:i + 2])
    a, b, c = np.polyfit(u, y[i - 1:i + 2], 2)
    vertex = -b / (2.0 * a)
    return float(np.exp(vertex)), float(c - b * b / (4.0 * a)), True


def interpolate(x, y, at, log_y=True):
    """y at ``at`` by linear interpolation in ln x (x rising) of ln y (``log_y``) or of y (for
    quantities near 1 or of either sign); NaN outside [x[0], x[-1]] (no extrapolation).

    With ``log_y``, an interval with an end at y <= 0 (the contact perimeter at full contact) has no
    ln y: it is interpolated linearly in y instead (ln of 0 would give 0 across the whole interval)."""
    x, y, at = np.asarray(x, float), np.asarray(y, float), np.asarray(at, float)
    if x.size == 0:
        return np.full(at.shape, np.nan)
    inside = (at >= x[0]) & (at <= x[-1])
    u, lx = np.log(at), np.log(x)
    out = np.interp(u, lx, y)
    if log_y:
        # NaN for ln y <= 0 spreads only to the intervals that touch it
        logged = np.exp(np.interp(u, lx, np.log(np.where(y > 0, y, np.nan))))
        out = np.where(np.isnan(logged), out, logged)
    return np.where(inside, out, np.nan)


def log_slope(x, y, at):
    """d ln y / d ln x at ``at`` from the two samples around it (NaN outside the range)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size < 2 or not x[0] <= at <= x[-1]:
        return np.nan
    j = min(max(int(np.searchsorted(x, at)), 1), x.size - 1)
    return float(np.log(y[j] / y[j - 1]) / np.log(x[j] / x[j - 1]))
