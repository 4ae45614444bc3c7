"""Past the paper: where the mean-field theory errs, contact morphology against v, sensitivity to gamma.

Relative error of the theory at a point: theory / numerics - 1 (theory at the point's sigma0, numerics
the seed mean); its standard error (theory / numerics) * se / numerics. Morphology: the /cases columns
(patches, mean_patch_area in m^2, perimeter in m, the two anisotropies), seed-averaged, read at fixed
A/A0 by interpolation in ln A/A0. gamma: the S(q) parameter of the theory (docs/conventions.md §5).
"""
import numpy as np

from vecontact.analysis.curves import interpolate
from vecontact.analysis.ensemble import select
from vecontact.analysis.paper import missing_note
from vecontact.analysis.study import recompute_theory
from vecontact.analysis.tables import AREA_BANDS, Table, band_label, in_band, num, percent, pm

#: (column, label, factor to the label's unit, interpolate/plot in log)
MORPHOLOGY = (("patches", "patches", 1.0, True),
              ("mean_patch_area", "mean patch area (μm²)", 1e12, True),
              ("perimeter", "perimeter (μm)", 1e6, True),
              ("anisotropy_extent", "extent x / y", 1.0, False),
              ("anisotropy_moments", "moments x / y", 1.0, False))
#: A/A0 at which morphology is compared across velocities.
MORPHOLOGY_AREAS = (0.01, 0.05, 0.2)
#: The gamma values compared: 0.45, the paper's 1/2, and 5/9.
GAMMAS = (0.45, 0.5, 5.0 / 9.0)


def theory_error(points, quantity):
    """(theory / numerics - 1, its standard error) per point for quantity 'mu' or 'area'."""
    ratio = points[f"theory_{quantity}"] / points[quantity]
    return ratio - 1.0, ratio * points[f"{quantity}_se"] / points[quantity]


def band_means(area, values, bands=AREA_BANDS):
    """Mean of ``values`` over the points whose A/A0 lies in each band (NaN for an empty band) and the
    number of points per band."""
    out, counts = [], []
    for band in bands:
        m = in_band(area, band)
        out.append(float(values[m].mean()) if m.any() else np.nan)
        counts.append(int(m.sum()))
    return np.array(out), counts


def theory_error_table(study):
    t = Table("theory_error", "Where the mean-field theory errs: theory / numerics - 1 in μ and A/A0, "
              "by numerical A/A0 band", ["q1", "v (m/s)"] + [f"A/A0 {band_label(b)}: μ; A" for b in AREA_BANDS])
    for q1 in study.q1_with_results():
        for v in study.velocities:
            p = select(study.points(), q1, v)
            if len(p) == 0:
                continue
            mu, n = band_means(p["area"], theory_error(p, "mu")[0])
            area, _ = band_means(p["area"], theory_error(p, "area")[0])
            cells = [f"{percent(m)}; {percent(a)} ({k})" if k else "—" for m, a, k in zip(mu, area, n)]
            t.rows.append([study.q1_label(q1), num(v)] + cells)
    t.notes = ["Mean over the seed-mean points of the band of theory/numerics - 1 (theory at the same sigma0); "
               "(k) = points in the band. Positive: the theory overestimates."] + missing_note(study)
    return t


def morphology_at_areas(points, areas=MORPHOLOGY_AREAS):
    """{column: (values, se)} at the given A/A0 for one (q1, v) curve of seed-mean points (rising load):
    each quantity interpolated in ln A/A0 (in ln of the quantity for the log ones), its standard error
    interpolated linearly in ln A/A0 likewise; NaN outside the curve's A/A0 range."""
    out = {}
    for col, _, _, log in MORPHOLOGY:
        out[col] = (interpolate(points["area"], points[col], areas, log_y=log),
                    interpolate(points["area"], points[f"{col}_se"], areas, log_y=False))
    return out


def morphology_table(study):
    t = Table("morphology", "Contact morphology against v at fixed A/A0",
              ["q1", "A/A0", "v (m/s)", "seeds"] + [label for _, label, _, _ in MORPHOLOGY])
    for q1 in study.q1_with_results():
        curves = {v: select(study.points(), q1, v) for v in study.velocities}
        at = {v: morphology_at_areas(p) for v, p in curves.items() if len(p) >= 2}
        for i, a in enumerate(MORPHOLOGY_AREAS):
            for v, m in at.items():
                cells = [pm(m[col][0][i] * f, m[col][1][i] * f) for col, _, f, _ in MORPHOLOGY]
                t.rows.append([study.q1_label(q1), num(a), num(v), num(int(curves[v]["n"].min()))] + cells)
    t.notes = ["Seed means interpolated to the A/A0 of the row (see morphology_at_areas); '—' where the "
               "A/A0 is outside the velocity's range or a seed has no non-percolating patch (anisotropy "
               "undefined). Patches are 4-connected on the torus; anisotropies > 1: elongated along the "
               "sliding direction x (vecontact.analysis.morphology)."] + missing_note(study)
    return t


def gamma_sensitivity(study):
    """Per (q1, v) with results: the points and the theory's mu at their sigma0 for each of GAMMAS,
    plus the largest change of the theory's A/A0 with gamma and the largest relative difference between
    the recomputed theory at the file's gamma and the file's theory_mu (a consistency check)."""
    rows, area_change, self_check = [], 0.0, 0.0
    for q1 in study.q1_with_results():
        for v in study.velocities:
            p = select(study.points(), q1, v)
            if len(p) == 0:
                continue
            th = {g: recompute_theory(study, q1, [v], p["pressure"], gamma=g) for g in GAMMAS}
            areas = np.array([r.area[0] for r in th.values()])
            area_change = max(area_change, float(np.max(np.abs(areas - areas[0]))))
            mine = recompute_theory(study, q1, [v], p["pressure"]).mu[0]
            self_check = max(self_check, float(np.max(np.abs(mine / p["theory_mu"] - 1.0))))
            rows.append(dict(q1=q1, velocity=v, points=p, mu={g: r.mu[0] for g, r in th.items()}))
    return rows, area_change, self_check


def gamma_curves(study, q1, gamma):
    """The theory's dense curves (area, mu), shape (V, J), at the file's curve pressures for ``gamma``."""
    th = study.theory(q1)
    res = [recompute_theory(study, q1, [v], th.curve_pressure[k], gamma) for k, v in enumerate(th.velocity)]
    return np.concatenate([r.area for r in res]), np.concatenate([r.mu for r in res])


def gamma_table(study):
    t = Table("gamma", "Sensitivity to γ: theory / numerics - 1 in μ for γ = 0.45, 0.5, 5/9",
              ["q1", "v (m/s)", "A/A0 band", "points"] + [f"γ = {g:.3g}" for g in GAMMAS])
    rows, area_change, self_check = gamma_sensitivity(study)
    for r in rows:
        p = r["points"]
        errs = {g: band_means(p["area"], mu / p["mu"] - 1.0) for g, mu in r["mu"].items()}
        for b, band in enumerate(AREA_BANDS):
            k = errs[GAMMAS[0]][1][b]
            if k:
                t.rows.append([study.q1_label(r["q1"]), num(r["velocity"]), band_label(band), str(k)]
                              + [percent(errs[g][0][b]) for g in GAMMAS])
    t.notes = ["Theory recomputed from the job in the file (vecontact.cases) at the points' sigma0; mean of "
               "theory/numerics - 1 over the seed-mean points of the band.",
               f"gamma changes only S(q), i.e. mu: the largest change of the theory's A/A0 between the "
               f"three gamma is {area_change:.1e} (absolute).",
               f"Check: the recomputed theory at the file's gamma = {study.gamma:g} matches the file's "
               f"theory_mu to {self_check:.1e} (largest relative difference)."] + missing_note(study)
    return t
