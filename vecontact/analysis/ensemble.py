"""Seed ensembles: the converged cases at one (q1, velocity, pressure) over surface realisations are one
point, the mean of each quantity with its standard error over the seeds.

Standard error of the mean: s / sqrt(n), s the sample standard deviation (ddof = 1) of the n converged
seeds; NaN when n = 1 (a single realisation says nothing about the spread; figures draw no error bar).
Unconverged rows (status -1) and theory-only rows (status 0) never enter a mean.
"""
import numpy as np

#: The key of a point: cases at the same key and different seeds are averaged.
POINT_KEY = ("q1", "velocity", "pressure")
#: Columns that do not depend on the seed (theory at the case's pressure, spectrum, grid): carried over.
SEED_FREE = ("theory_area", "theory_mu", "xi", "slope_rms", "N")
#: Numerical results averaged by default (dimensionless, except mean_patch_area m^2 and perimeter m).
RESULTS = ("area", "mu", "mu_geometric", "patches", "percolating", "mean_patch_area", "perimeter",
           "anisotropy_extent", "anisotropy_moments")


def converged_rows(cases):
    """The /cases rows that are numerical results: converged ones only (status 1). Rows that did not
    converge (status -1) keep finite numbers in the file for inspection but are never drawn or averaged;
    theory-only rows (status 0) have none."""
    return cases[cases["status"] == 1]


def standard_error(values):
    """Standard error of the mean of a 1-D sample: std(ddof=1) / sqrt(n); NaN when n < 2."""
    values = np.asarray(values, dtype=float).ravel()
    return float(np.std(values, ddof=1) / np.sqrt(values.size)) if values.size >= 2 else np.nan


def seed_points(cases, quantities=RESULTS):
    """Seed-averaged points of the converged rows of ``cases`` (a /cases table).

    Returns a structured array sorted by (q1, velocity, pressure) with the key columns, ``n`` (converged
    seeds averaged), the :data:`SEED_FREE` columns, and for each quantity ``<name>`` (mean over seeds)
    and ``<name>_se`` (standard error, NaN for n = 1). A quantity that is NaN for one seed (e.g. an
    anisotropy with only percolating patches) has a NaN mean: nothing is silently dropped.
    """
    rows = converged_rows(cases)
    fields = [(k, "f8") for k in POINT_KEY] + [("n", "i8")] + [(k, "f8") for k in SEED_FREE]
    fields += [(f"{q}{suffix}", "f8") for q in quantities for suffix in ("", "_se")]
    if len(rows) == 0:
        return np.zeros(0, dtype=fields)
    keys = np.stack([rows[k].astype(float) for k in POINT_KEY], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    out = np.zeros(len(unique), dtype=fields)
    for i, key in enumerate(unique):
        members = rows[inverse.ravel() == i]
        for k, value in zip(POINT_KEY, key):
            out[i][k] = value
        out[i]["n"] = len(members)
        for k in SEED_FREE:
            out[i][k] = members[k][0]
        for q in quantities:
            values = members[q].astype(float)
            out[i][q] = values.mean()
            out[i][f"{q}_se"] = standard_error(values)
    return out


def select(points, q1=None, velocity=None):
    """The points at one q1 and/or velocity, in rising pressure."""
    keep = np.ones(len(points), bool)
    if q1 is not None:
        keep &= points["q1"] == q1
    if velocity is not None:
        keep &= points["velocity"] == velocity
    return np.sort(points[keep], order="pressure")


def seeds_summary(points):
    """'n = 4' when every point has 4 seeds, 'n = 2-4' when it varies, '' for no points."""
    if len(points) == 0:
        return ""
    lo, hi = int(points["n"].min()), int(points["n"].max())
    return f"n = {lo}" if lo == hi else f"n = {lo}-{hi}"
