"""The numbers behind the paper's claims (Scaraggi & Persson 2015), from the seed-averaged points.

Each ``*_table`` returns a :class:`~vecontact.analysis.tables.Table`; the functions without that
suffix return the numbers (tested on synthetic data). Conventions: A/A0 and mu dimensionless, sigma0 in
Pa, x = sigma0 / (E0 h'_rms) (Fig. 4) or sigma0 / (E0 xi(v)) (Fig. 5); mu_num / mu_theory compares the
seed mean with the theory at the same pressure. Only converged cases enter (see ``ensemble``).
"""
import numpy as np

from vecontact.analysis.curves import (collapse_scatter, erf_small_load_slope, interpolate, log_slope,
                                       peak, small_load_slope)
from vecontact.analysis.ensemble import select
from vecontact.analysis.study import recompute_theory
from vecontact.analysis.tables import Table, num, pm

#: A/A0 at which the friction regime is read (the paper: "at A/A0 ~ 0.05 the small system is still in
#: the Hertzian friction regime, whereas the large system is experiencing the transition").
REGIME_AREA = 0.05
#: Common pressures per q1 at which A/A0 is compared across velocities (across the overlap of ranges).
COMMON_PRESSURES = 3


def missing_note(study):
    """Notes for the q1 without converged numerics (seeds per q1: the seeds table)."""
    have = study.q1_with_results()
    return [f"q1 = {study.q1_label(q)}: no converged numerical cases in this file yet"
            for q in study.q1s if q not in have]


def friction_peaks(study):
    """Per (q1, v): the maximum of the numerical mu(A/A0) (see curves.peak), mu at the lowest load, the
    rise mu_max / mu_lowest - 1 with its size in standard errors, d ln mu / d ln A at A/A0 = 0.05, and
    the same peak and rise of the theory at the same sigma0."""
    out = []
    for q1 in study.q1_with_results():
        for v in study.velocities:
            p = select(study.points(), q1, v)
            if len(p) < 2:
                continue
            a_peak, mu_peak, interior = peak(p["area"], p["mu"])
            a_theory, mu_theory, theory_interior = peak(p["theory_area"], p["theory_mu"])
            top = int(np.argmax(p["mu"]))
            sigma = np.hypot(p["mu_se"][top], p["mu_se"][0])
            out.append(dict(q1=q1, velocity=v, n=int(p["n"].min()), area=a_peak, interior=interior,
                            pressure=float(interpolate(p["area"], p["pressure"], a_peak)), mu=mu_peak,
                            mu_lowest=float(p["mu"][0]), rise=mu_peak / p["mu"][0] - 1.0,
                            rise_in_se=(p["mu"][top] - p["mu"][0]) / sigma if sigma > 0 else np.nan,
                            slope=log_slope(p["area"], p["mu"], REGIME_AREA),
                            theory_area=a_theory, theory_interior=theory_interior,
                            theory_rise=mu_theory / p["theory_mu"][0] - 1.0))
    return out


def friction_peaks_table(study):
    t = Table("peak", "Friction peak at small load (Fig. 2): where mu(A/A0) is largest",
              ["q1", "v (m/s)", "seeds", "A/A0 at max", "σ0 at max (Pa)", "μ max", "μ lowest load",
               "rise", "rise / s.e.", "d ln μ / d ln A at A/A0 = 0.05", "theory: A/A0 at max", "theory: rise"])
    for r in friction_peaks(study):
        t.rows.append([study.q1_label(r["q1"]), num(r["velocity"]), num(r["n"]), _where(r["area"], r["interior"]),
                       num(r["pressure"]), num(r["mu"], 4), num(r["mu_lowest"], 4), f"{100 * r['rise']:+.1f} %",
                       num(r["rise_in_se"], 2), num(r["slope"], 2), _where(r["theory_area"], r["theory_interior"]),
                       f"{100 * r['theory_rise']:+.1f} %"])
    t.notes = ["Peak: the largest seed-mean mu, refined by the parabola through it and its two neighbours "
               "in (ln A/A0, mu); sigma0 at the peak interpolated in ln sigma0 vs ln A/A0. 'none inside': the "
               "largest mu is at an end of the load range (no interior maximum).",
               "rise = mu_max / mu(lowest load) - 1; 'rise / s.e.' = (largest sample - lowest-load sample) / "
               "sqrt(se_1^2 + se_2^2) over seeds ('—' with one seed). 'theory': the same for the theory's mu "
               "and A/A0 at the same sigma0.",
               "d ln mu / d ln A > 0: friction still rises with load (Hertzian regime); < 0: past the peak."]
    t.notes += missing_note(study)
    return t


def _where(area, interior):
    return num(area) if interior else f"none inside ({num(area)}: an end)"


def high_load_ratios(study):
    """Per (q1, v): numerics / theory at the highest converged load (mu and A/A0, with s.e.)."""
    out = []
    for q1 in study.q1_with_results():
        for v in study.velocities:
            p = select(study.points(), q1, v)
            if len(p) == 0:
                continue
            top = p[-1]
            out.append(dict(q1=q1, velocity=v, n=int(top["n"]), pressure=float(top["pressure"]),
                            area=float(top["area"]), mu_ratio=top["mu"] / top["theory_mu"],
                            mu_ratio_se=top["mu_se"] / top["theory_mu"], area_ratio=top["area"] / top["theory_area"],
                            area_ratio_se=top["area_se"] / top["theory_area"]))
    return out


def high_load_table(study):
    t = Table("high_load", "Numerics against theory at the highest load (Fig. 2: convergence to the theory)",
              ["q1", "v (m/s)", "seeds", "σ0 (Pa)", "A/A0 (num)", "μ_num / μ_theory", "A_num / A_theory"])
    for r in high_load_ratios(study):
        t.rows.append([study.q1_label(r["q1"]), num(r["velocity"]), num(r["n"]), num(r["pressure"]),
                       num(r["area"]), pm(r["mu_ratio"], r["mu_ratio_se"]),
                       pm(r["area_ratio"], r["area_ratio_se"])])
    t.notes = ["Theory at the same sigma0 (the /cases columns theory_mu, theory_area); ± is the standard "
               "error over seeds of the numerical mean divided by the theory."] + missing_note(study)
    return t


def area_against_velocity(study):
    """Per q1: A/A0 at common sigma0 for every v (ln A interpolated in ln sigma0, no extrapolation),
    at COMMON_PRESSURES values spread over the overlap of the slowest and fastest velocity's ranges;
    with the theory's ratio A(v_max)/A(v_min) at the same sigma0."""
    out = []
    vmin, vmax = min(study.velocities), max(study.velocities)
    for q1 in study.q1_with_results():
        lo_pts, hi_pts = select(study.points(), q1, vmin), select(study.points(), q1, vmax)
        if len(lo_pts) < 2 or len(hi_pts) < 2:
            out.append(dict(q1=q1, pressure=np.nan, note=f"needs converged points at v = {vmin:g} and {vmax:g}"))
            continue
        lo, hi = max(lo_pts["pressure"][0], hi_pts["pressure"][0]), min(lo_pts["pressure"][-1], hi_pts["pressure"][-1])
        if lo >= hi:
            out.append(dict(q1=q1, pressure=np.nan, note=f"no common sigma0 at v = {vmin:g} and {vmax:g}"))
            continue
        common = np.geomspace(lo, hi, COMMON_PRESSURES)
        th = recompute_theory(study, q1, [vmin, vmax], common).area
        by_v = {v: select(study.points(), q1, v) for v in study.velocities}
        for k, s in enumerate(common):
            areas = {v: float(interpolate(by_v[v]["pressure"], by_v[v]["area"], s)) for v in study.velocities}
            out.append(dict(q1=q1, pressure=float(s), areas=areas, ratio=areas[vmax] / areas[vmin],
                            theory_ratio=float(th[1, k] / th[0, k]), note=""))
    return out


def area_against_velocity_table(study):
    vs = study.velocities
    t = Table("area_vs_v", f"A/A0 falls with v at fixed σ0 (Fig. 4): from v = {min(vs):g} to {max(vs):g} m/s",
              ["q1", "σ0 (Pa)"] + [f"A/A0 at {v:g} m/s" for v in vs]
              + [f"A({max(vs):g}) / A({min(vs):g})", "theory ratio"])
    for r in area_against_velocity(study):
        if r["note"]:
            t.rows.append([study.q1_label(r["q1"]), "—"] + ["—"] * len(vs) + [r["note"], "—"])
            continue
        t.rows.append([study.q1_label(r["q1"]), num(r["pressure"])] + [num(r["areas"][v]) for v in vs]
                      + [num(r["ratio"]), num(r["theory_ratio"])])
    t.notes = ["Seed-mean A/A0 interpolated linearly in (ln sigma0, ln A/A0) between the sweep's pressures "
               "('—': outside that velocity's range); sigma0 at both ends and the geometric middle of the "
               "overlap of the slowest and fastest velocity's ranges; theory recomputed at those sigma0."]
    t.notes += missing_note(study)
    return t


def abscissa(study, points, scale):
    """x of Fig. 4 (scale 'slope': sigma0 / (E0 h'_rms)) or Fig. 5 (scale 'xi': sigma0 / (E0 xi(v)))."""
    return points["pressure"] / (study.E0 * (points["slope_rms"] if scale == "slope" else points["xi"]))


def collapse(study, velocities=None):
    """Scatter of ln A/A0 around one fitted curve (curves.collapse_scatter) in the Fig. 4 and Fig. 5
    abscissas, for the numerics and for the theory at the same pressures, over the given velocities
    (default: all) and every q1 with results. Returns {scale: (numerics, theory, points, q1 values)}:
    the last two count the seed-mean points and the distinct q1 of this group."""
    pts = study.points()
    if velocities is not None:
        pts = pts[np.isin(pts["velocity"], velocities)]
    out = {}
    for scale in ("slope", "xi"):
        x = abscissa(study, pts, scale)
        out[scale] = (collapse_scatter(x, pts["area"]), collapse_scatter(x, pts["theory_area"]), len(pts),
                      len(np.unique(pts["q1"])))
    return out


def collapse_table(study):
    t = Table("collapse", "Collapse of A/A0: rms scatter of ln A/A0 around one fitted curve (Figs. 4, 5)",
              ["abscissa", "velocities", "q1 with results", "points", "scatter (numerics)", "scatter (theory)"])
    names = {"slope": "σ0/(E0 h'_rms) (Fig. 4)", "xi": "σ0/(E0 ξ) (Fig. 5)"}
    groups = [("all", None)] + [(f"{v:g} m/s", [v]) for v in study.velocities]
    for scale in ("slope", "xi"):
        for label, vs in groups:
            s_num, s_th, n, nq = collapse(study, vs)[scale]
            t.rows.append([names[scale], label, str(nq), str(n), num(s_num), num(s_th)])
    t.notes = ["Fit: one curve A = erf(exp(P(ln x))) through all the seed-mean points of the group (every q1 "
               "with results), P a least-squares cubic in ln x fitted to ln erfinv(A/A0) "
               "(vecontact.analysis.curves); scatter = rms of ln A - ln A_fit (≈ rms relative deviation). "
               "'theory': the same fit through the theory's A/A0 at the same sigma0 (on Fig. 5 the theory is "
               "the single erf curve, which the family holds: scatter 0 to rounding).",
               "Per-velocity rows with one q1 measure the noise around a single curve, not a collapse."]
    t.notes += missing_note(study)
    return t


def master_slope(study, q1=None):
    """(kappa, s.e., points) of the numerical master curve A/A0 ~ kappa sigma0 / (E0 xi), from the
    seed-mean points with A/A0 < 5 % (curves.small_load_slope), over all q1 or one."""
    pts = study.points() if q1 is None else select(study.points(), q1)
    return small_load_slope(abscissa(study, pts, "xi"), pts["area"])


def master_slope_table(study):
    kt = erf_small_load_slope(study.nu)
    t = Table("kappa", "Small-load slope κ of the master curve: A/A0 ≈ κ σ0/(E0 ξ) (Fig. 5)",
              ["q1", "points (A/A0 < 5 %)", "κ numerics", "κ theory", "κ_num / κ_theory",
               "κ/(1-ν²) numerics (E* units)", "κ/(1-ν²) theory"])
    plane = 1.0 - study.nu ** 2
    for label, q1 in [("all", None)] + [(study.q1_label(q), q) for q in study.q1_with_results()]:
        k, se, n = master_slope(study, q1)
        t.rows.append([label, str(n), pm(k, se), num(kt, 4), pm(k / kt, se / kt), pm(k / plane, se / plane),
                       num(kt / plane, 4)])
    t.notes = [f"κ theory = 2 sqrt(2) (1 - nu^2) / sqrt(pi) = {kt:.4f} (nu = {study.nu:g}), the slope of "
               "A/A0 = erf(sqrt(2) (1 - nu^2) x) at x = 0.",
               "κ numerics = exp(mean ln(A/x)) over the seed-mean points with A/A0 < 5 % (unit slope in "
               "log-log imposed); ± = standard error of that mean across points.",
               "κ/(1-ν²): the same slope against σ0/(E* ξ), E* = E0/(1-ν²), the units of the elastic "
               "literature (theory: sqrt(8/π) = 1.596)."] + missing_note(study)
    return t


def roughness_table(study):
    t = Table("hrms", "Roughness of the four spectra (h_rms ≈ 27 nm)",
              ["q1", "h_rms (nm)", "h'_rms = <(∇h)^2>^1/2"] + [f"ξ({v:g} m/s)" for v in study.velocities])
    for th in study.theories:
        t.rows.append([study.q1_label(th.q1), f"{th.hrms * 1e9:.2f}", num(th.slope_rms, 4)]
                      + [num(x, 4) for x in th.xi])
    t.notes = ["From /theory/q1_<i> attributes hrms, slope_rms and dataset xi (the job's spectrum, not a "
               "realisation)."]
    return t
