"""The sweep itself: seeds per q1, convergence counts, cost in core-hours, and the Fig. 3 map cases."""
import numpy as np

from vecontact.analysis.beyond import MORPHOLOGY
from vecontact.analysis.tables import Table, num

#: The morphology columns of the maps table after the patch count (an integer, printed as one).
SIZES = [m for m in MORPHOLOGY if m[0] != "patches"]


def _grid(study, q1):
    """N at q1; a dash for a height file (not read: the report reads the results file only)."""
    s = study.job.surface
    return "—" if s.spectrum == "file" else s.grid(q1)


def seeds_table(study):
    t = Table("seeds", "Surface realisations (seeds) per q1",
              ["q1", "N", "seeds in the job", "seeds with converged cases", "points", "points with every seed"])
    pts = study.points()
    for q1 in study.q1s:
        want = study.seeds(q1)
        conv = study.converged()
        have = sorted({int(s) for s in conv["seed"][conv["q1"] == q1]})
        mine = pts[pts["q1"] == q1]
        t.rows.append([study.q1_label(q1), str(_grid(study, q1)), ", ".join(map(str, want)),
                       ", ".join(map(str, have)) or "none", str(len(mine)), str(int((mine["n"] == len(want)).sum()))])
    t.notes = ["A point = one (q1, v, sigma0), averaged over its converged seeds; the figures' error bars are "
               "the standard error over those seeds (none for a single seed)."]
    return t


def friction_estimates_table(study):
    """The two numerical friction estimates (docs/conventions.md §4) against each other, per (q1, v)."""
    t = Table("friction_estimates", "The two numerical friction estimates agree (a check of the numerics)",
              ["q1", "v (m/s)", "cases", "mean of μ_geometric / μ_dissipation - 1",
               "largest abs(μ_geometric / μ_dissipation - 1)"])
    conv = study.converged()
    for q1 in study.q1_with_results():
        for v in study.velocities:
            r = conv[(conv["q1"] == q1) & (conv["velocity"] == v)]
            if len(r):
                d = r["mu_geometric"] / r["mu"] - 1.0
                t.rows.append([study.q1_label(q1), num(v), str(len(r)), f"{d.mean():+.1e}",
                               f"{np.abs(d).max():.1e}"])
    t.notes = ["Every converged case: mu_geometric = <p dh/dx> / sigma0, mu (the one in the figures and tables) = "
               "the dissipated power; they differ by discretisation error only."]
    return t


def convergence_counts(study):
    """Per q1: (expected cases, converged, not converged, not yet solved)."""
    expected = study.expected_cases()
    out = {}
    for q1 in study.q1s:
        rows = study.cases[study.cases["q1"] == q1]
        n_exp = sum(1 for c in expected if c[0] == q1)
        conv, fail = int((rows["status"] == 1).sum()), int((rows["status"] == -1).sum())
        out[q1] = (n_exp, conv, fail, n_exp - conv - fail)
    return out


def convergence_table(study):
    t = Table("convergence", "Convergence of the numerical cases",
              ["q1", "N", "cases in the job", "converged", "NOT converged", "not solved yet"])
    for q1, (n, conv, fail, left) in convergence_counts(study).items():
        t.rows.append([study.q1_label(q1), str(_grid(study, q1)), str(n), str(conv), str(fail), str(left)])
    t.notes = [f"File {'complete' if study.attrs.get('complete') else 'INCOMPLETE (sweep still running)'}. "
               "Unconverged cases (status -1) are in none of the figures or other tables."]
    return t


def core_hours(cases):
    """{N: (cases with a wall time, core-hours = sum(seconds * ranks) / 3600, ranks per case)} over
    every solved row (converged or not: both cost)."""
    out = {}
    timed = cases[np.isfinite(cases["seconds"]) & (cases["ranks"] >= 1)]
    for N in sorted({int(n) for n in timed["N"]}):
        r = timed[timed["N"] == N]
        out[N] = (len(r), float(np.sum(r["seconds"] * r["ranks"])) / 3600.0, sorted({int(k) for k in r["ranks"]}))
    return out


def cost_table(study):
    t = Table("cost", "Cost of the sweep per grid size",
              ["N", "cases solved", "core-hours", "core-seconds per case", "ranks per case"])
    for N, (n, hours, ranks) in core_hours(study.cases).items():
        t.rows.append([str(N), str(n), num(hours), num(3600 * hours / n), ", ".join(map(str, ranks))])
    t.notes = ["core-hours = sum over /cases rows of seconds x ranks / 3600 (wall time of each solve times "
               "the ranks that solved it; theory and file writing not included)."]
    return t


def maps_table(maps):
    """The contact-map cases of Fig. 3 (``maps``: the Study of the maps file)."""
    t = Table("maps", "The contact maps of Fig. 3",
              ["q1", "N", "seed", "v (m/s)", "σ0 (Pa)", "A/A0", "percolating", "patches"]
              + [label for _, label, _, _ in SIZES])
    for r in maps.converged():
        t.rows.append([maps.q1_label(r["q1"]), str(int(r["N"])), str(int(r["seed"])), num(r["velocity"]),
                       num(r["pressure"]), num(r["area"]), str(int(r["percolating"])), str(int(r["patches"]))]
                      + [num(r[col] * f) for col, _, f, _ in SIZES])
    t.notes = [f"From {maps.path} (converged cases only)."]
    t.notes += [f"q1 = {maps.q1_label(q)}: no converged map case yet" for q in maps.q1s
                if q not in maps.q1_with_results()]
    return t
