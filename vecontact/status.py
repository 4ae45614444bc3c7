"""``vecontact status RESULTS.h5``: how far a sweep has got and what failed, from its results file.

Reads the file only (no MPI, no PETSc): safe to run while the sweep writes it (each commit replaces
the file atomically).  The job's full case list comes from ``/theory`` (the pressures of every
(q1, v)) and the seeds of the stored job; a case is "to solve" until ``/cases`` has its row.
"""
import json

import numpy as np
import yaml

from vecontact.io.results import open_for_reading, read_strings
from vecontact.jobtypes import Job
from vecontact.rows import REASON, case_key


def read_status(path):
    """dict with the job's cases, the finished rows, the runs log and the diagnostics of failures.

    Raises InputError (key ``results``) for a missing or foreign file."""
    with open_for_reading(path) as f:
        job = Job.from_dict(yaml.safe_load(f.attrs["job_yaml"]))
        expected = []
        for name in f["theory"]:
            g = f["theory"][name]
            q1 = float(g.attrs["q1"])
            for seed in job.surface.realisations(q1):
                for i, v in enumerate(g["velocity"][()]):
                    expected += [(q1, int(seed), float(v), float(p)) for p in g["pressure"][i]]
        cases = f["cases"][()]
        diag = read_strings(f, "diagnostics", len(cases))
        runs = [json.loads(r) for r in read_strings(f, "runs")]
        complete = bool(f.attrs.get("complete", False))
    return dict(job=job, expected=sorted(set(expected)), cases=cases, diagnostics=diag, runs=runs,
                complete=complete, numerics=bool(job.numerics.enabled))


def format_status(path, st):
    """The report as a list of lines."""
    cases, expected = st["cases"], st["expected"]
    done = {case_key(r) for r in cases}
    status = cases["status"]
    lines = []
    if not st["numerics"]:
        lines.append(f"{path}: theory only ({len(cases)} of {len(expected)} cases written"
                     f"{', complete' if st['complete'] else ''})")
        return lines
    nconv, nfail = int((status == 1).sum()), int((status == -1).sum())
    left = [c for c in expected if c not in done]
    lines.append(f"{path}: {len(expected)} cases: {nconv} converged, {nfail} NOT converged, "
                 f"{len(left)} to solve{' (complete)' if st['complete'] else ''}")
    lines.append(f"{'q1 (1/m)':>10} {'seed':>4} {'v (m/s)':>8} {'N':>5}  {'conv/total':>10} {'failed':>6}  "
                 f"{'A/A0 converged':>17}  {'max s':>7}  {'core-h':>6}")
    groups = sorted({(c[0], c[1], c[2]) for c in expected})
    for q1, seed, v in groups:
        total = sum(1 for c in expected if c[:3] == (q1, seed, v))
        sel = (cases["q1"] == q1) & (cases["seed"] == seed) & (cases["velocity"] == v)
        rows = cases[sel]
        ok = rows[rows["status"] == 1]
        area = f"{ok['area'].min():.4f}-{ok['area'].max():.4f}" if len(ok) else "-"
        N = int(rows["N"].max()) if len(rows) else _grid(st["job"].surface, q1)
        secs = rows["seconds"][np.isfinite(rows["seconds"])]
        core_h = float(np.sum(secs * np.maximum(rows["ranks"][np.isfinite(rows["seconds"])], 1))) / 3600
        lines.append(f"{q1:10.4g} {seed:4d} {v:8.4g} {N:5d}  {len(ok):>4d}/{total:<5d} "
                     f"{int((rows['status'] == -1).sum()):6d}  {area:>17}  "
                     f"{(secs.max() if len(secs) else 0):7.0f}  {core_h:6.2f}")
    failed = [(r, d) for r, d in zip(cases, st["diagnostics"]) if r["status"] == -1]
    if failed:
        lines.append("NOT converged (their numerical columns are not results):")
        for r, d in failed:
            reason = json.loads(d).get(REASON, "?") if d else "?"
            lines.append(f"  q1={r['q1']:.4g} seed={r['seed']} v={r['velocity']:.4g} p={r['pressure']:.4g}: "
                         f"residual {r['residual']:.2e}, {reason}, {r['iterations']} Newton steps")
    if st["runs"]:
        lines.append("runs:")
        for run in st["runs"]:
            n = int((cases["run"] == run["run"]).sum()) if "run" in cases.dtype.names else 0
            lines.append(f"  {run['run']}: {run['started']}  {run['git_commit'][:12]}"
                         f"{'+dirty' if run['git_commit'].endswith('+dirty') else ''}  "
                         f"{run['nranks']} ranks on {run['host']}  {n} rows")
    if "run" in cases.dtype.names and (cases["run"] == -1).any():
        lines.append(f"  ({int((cases['run'] == -1).sum())} rows written before the runs log existed)")
    return lines


def _grid(surface, q1):
    """N of a generated surface at q1; 0 for a height file (not read here: status reads the results only)."""
    return 0 if surface.spectrum == "file" else surface.grid(q1)


def status(path):
    """Print the report; exit status 0 (the sweep may be unfinished: that is not an error)."""
    print("\n".join(format_status(path, read_status(path))))
    return 0
