"""What a sweep cost, per grid size and per code version, from its results file (issue #15).

Usage (from the repository root):
    python benchmarks/study_cost.py results/paper.h5 [--reference OTHER.h5] [--n 4096]
                                    [--machine-commit PREFIX]

Core-hours are the solver's own seconds times the ranks of each case (``/cases`` columns ``seconds``
and ``ranks``: the solve, not the theory, the file or the farm's waits), summed over the converged
cases; the code version of a row is the ``git_commit`` of its run in ``/runs`` (rows grouped by it).  With ``--reference``
the cases converged in both files (same q1, seed, velocity and pressure) are compared: A/A0 in
contact points (|dA| N^2) and mu relative, and what they cost in each file (FFT pairs and core-hours,
summed per N and velocity over those cases only, so a partial rerun is comparable case for case).
Output: tables, then as LAST line one JSON object with ``core_hours`` per N, converged ``cases`` and
``planned`` cases (the stored job's) per N, ``core_hours_n`` (the grid of ``--n``; null until all its
planned cases converged) and, with a reference, ``compared``, ``max_points``, ``max_mu_rel`` and
``ratios`` per N (``pairs`` and ``core_hours``: this file's sums over the reference's, same cases;
``machine``: the time ratio over the cases whose FFT pairs are equal in both, i.e. solved the same
way, which measures the two runs' machines; ``core_hours_same_machine``: core_hours at the
reference's machine speed; ``cases`` and ``same_path``: the compared cases and those with equal
pairs) and ``runs`` (the same ratios for each run of this file, keyed by its ``/runs`` index; the
table shows the run's commit and start).  A file resumed in several runs (several sessions) can have
a different machine speed in each: ``core_hours_same_machine`` divides each run's core-seconds by
that run's own ``machine`` (null when a run has no same-path case), while ``machine`` stays the
ratio over all runs' same-path cases together.  The reference's runs count as one machine.
``--machine-commit PREFIX`` keeps only this file's rows solved by a commit starting with PREFIX in
``machine``: a later code version can take the same path at another speed.  It says the runs shared
one machine, so ``core_hours_same_machine`` then divides every run by that one ratio.

The pace probe (files written since session 43): the farm times a float64 FFT pair on each case's
grid and ranks right after its solve (``raw_pair_seconds`` in /diagnostics, farm/case.py).  ``paced``
per N (null unless every converged case has one) gives ``time_per_pair`` (seconds over pairs x raw
pair: #15's measure, from the study itself), ``raw_pair_units`` (core-seconds over each case's raw
pair: a cost the machine's pace is divided out of) and the median ``raw_pair``; against a reference
that has probes too, ``ratios[N]["paced"]`` is the ratio of the two raw_pair_units over the cases
probed in both (``probed``), with no need for cases that took the same path.
"""
import argparse
import json
import os
import sys

import numpy as np
from numpy.lib import recfunctions

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from vecontact.status import read_status  # noqa: E402

KEY = ("q1", "seed", "velocity", "pressure")


def load(path):
    """(/cases structured array, {run index: git commit}, {N: cases the job plans}, {run index: start
    time}) of a results file (read by :func:`vecontact.status.read_status`).  The cases get one more
    column, ``raw_pair_seconds``: the farm's pace probe of each case from /diagnostics (NaN where the
    file has none: files before session 43, or diagnostics not aligned with /cases)."""
    st = read_status(path)
    diag = st["diagnostics"]
    pace = np.full(len(st["cases"]), np.nan)
    if len(diag) == len(st["cases"]):
        for i, d in enumerate(diag):
            probe = json.loads(d).get("raw_pair_seconds") if d else None
            pace[i] = np.nan if probe is None else float(probe)
    cases = recfunctions.append_fields(st["cases"], "raw_pair_seconds", pace, usemask=False)
    runs = {int(r["run"]): str(r.get("git_commit") or "?")[:10] for r in st["runs"]}
    started = {int(r["run"]): str(r.get("started") or "?") for r in st["runs"]}
    q1s = [q1 for q1, *_ in st["expected"]]
    grids = {q1: st["job"].surface.grid(q1) for q1 in set(q1s)}    # once per q1 (a height file is read)
    planned = {}
    for q1 in q1s:
        planned[grids[q1]] = planned.get(grids[q1], 0) + 1
    return cases, runs, planned, started


def cost(cases, runs):
    """Rows (N, commit, converged, failed, core-hours, median FFT pairs) and the totals per N."""
    rows, per_n, count = [], {}, {}
    commit = np.array([runs.get(int(r), "?") for r in cases["run"]])
    for N in np.unique(cases["N"]):
        at_n = cases["N"] == N
        for c in sorted(set(commit[at_n])):
            m = at_n & (commit == c)
            ok = m & (cases["converged"] == 1)
            hours = float((cases["seconds"][ok] * cases["ranks"][ok]).sum() / 3600.0)
            pairs = float(np.median(cases["fft_pairs"][ok])) if ok.any() else float("nan")
            rows.append((int(N), c, int(ok.sum()), int((m & ~ok).sum()), hours, pairs))
            per_n[int(N)] = per_n.get(int(N), 0.0) + hours
            count[int(N)] = count.get(int(N), 0) + int(ok.sum())
    return rows, per_n, count


def paced(cases):
    """Per N, over its converged cases, when every one of them has a pace probe: ``time_per_pair`` =
    sum of seconds / sum of (FFT pairs x raw pair seconds), and ``raw_pair_units`` = sum of ranks x
    seconds / raw pair seconds (the core-seconds counted in raw pairs of each case's own moment: the
    cost with the machine's pace divided out), ``raw_pair`` the median probe (s).  {N: dict or None}."""
    out = {}
    for N in np.unique(cases["N"]):
        c = cases[(cases["N"] == N) & (cases["converged"] == 1)]
        if not len(c) or np.isnan(c["raw_pair_seconds"]).any():
            out[int(N)] = None
            continue
        out[int(N)] = dict(time_per_pair=float(c["seconds"].sum() / (c["fft_pairs"] * c["raw_pair_seconds"]).sum()),
                           raw_pair_units=float((c["seconds"] * c["ranks"] / c["raw_pair_seconds"]).sum()),
                           raw_pair=float(np.median(c["raw_pair_seconds"])))
    return out


SAME_PATH_RTOL = 1e-9   # FFT pairs equal to this: the case took the same path through the solver


def compare(cases, ref, machine=None):
    """Cases converged in both: (count, max |dA/A0| N^2 in points, max relative d mu, sums, by_run)
    with sums[(N, velocity)] = array [cases, pairs here, pairs in ref, core-seconds here, core-seconds
    in ref, the same two core-seconds over the cases whose FFT pairs are equal in both files and, if
    given, whose entry of the bool array ``machine`` (aligned with ``cases``) is True, the core-seconds
    over each case's raw pair here and in ref over the cases probed in both, and those cases], and
    by_run[(N, run)] the same sums over this file's cases of each run (its ``/cases`` column ``run``)."""
    index = {tuple(float(r[k]) for k in KEY): r for r in ref[ref["converged"] == 1]}
    n, points, mu, sums, by_run = 0, 0.0, 0.0, {}, {}
    usable = np.ones(len(cases), dtype=bool) if machine is None else np.asarray(machine, dtype=bool)
    for r, use in zip(cases[cases["converged"] == 1], usable[cases["converged"] == 1]):
        o = index.get(tuple(float(r[k]) for k in KEY))
        if o is None:
            continue
        n += 1
        points = max(points, abs(float(r["area"]) - float(o["area"])) * float(r["N"]) ** 2)
        mu = max(mu, abs(float(r["mu"]) / float(o["mu"]) - 1.0))
        here, there = float(r["seconds"] * r["ranks"]), float(o["seconds"] * o["ranks"])
        same = use and abs(float(r["fft_pairs"]) - float(o["fft_pairs"])) <= SAME_PATH_RTOL * float(o["fft_pairs"])
        probed = not (np.isnan(r["raw_pair_seconds"]) or np.isnan(o["raw_pair_seconds"]))
        units = (here / r["raw_pair_seconds"], there / o["raw_pair_seconds"]) if probed else (0.0, 0.0)
        row = np.array([1, r["fft_pairs"], o["fft_pairs"], here, there, here * same, there * same, same,
                        *units, probed], dtype=float)
        key = (int(r["N"]), float(r["velocity"]))
        sums[key] = sums.get(key, 0.0) + row
        key = (int(r["N"]), int(r["run"]))
        by_run[key] = by_run.get(key, 0.0) + row
    return n, points, mu, sums, by_run


def _ratios(t):
    """``pairs``, ``core_hours`` (here / ref), ``machine`` (core-seconds here / ref over the same-path
    cases: the two machines' speed ratio, null without such cases), ``paced`` (core-seconds in raw
    pairs here / ref over the ``probed`` cases, those with a pace probe in both files: the code's cost
    ratio with each case's machine pace divided out, null without such cases) of one array of
    compare's sums."""
    machine = float(t[5] / t[6]) if t[6] > 0 else None
    return dict(cases=int(t[0]), same_path=int(t[7]), pairs=float(t[1] / t[2]), core_hours=float(t[3] / t[4]),
                machine=machine, probed=int(t[10]), paced=float(t[8] / t[9]) if t[10] > 0 else None)


def ratios(sums, by_run, per_run=True):
    """Per N over every velocity of ``sums`` and every run of ``by_run`` (compare): :func:`_ratios`,
    ``core_hours_same_machine`` (this file's core-seconds, each run's divided by its own ``machine``,
    over the reference's; null if a run has no same-path case; without ``per_run``, all of them by the
    pooled ``machine``) and ``runs`` ({run: _ratios})."""
    out = {}
    for (N, _), s in sums.items():
        out[N] = out.get(N, 0.0) + s
    res = {}
    for N, t in out.items():
        pooled = _ratios(t)
        runs = {run: _ratios(s) for (n, run), s in sorted(by_run.items()) if n == N}
        machines = {run: r["machine"] if per_run else pooled["machine"] for run, r in runs.items()}
        at_ref_speed = [by_run[N, run][3] / m if m else None for run, m in machines.items()]
        res[N] = dict(pooled, runs=runs,
                      core_hours_same_machine=None if None in at_ref_speed else float(sum(at_ref_speed) / t[4]))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--reference", help="another results file of the same job: cases compared")
    ap.add_argument("--n", type=int, default=4096, help="grid whose total is reported as core_hours_n")
    ap.add_argument("--machine-commit", metavar="PREFIX",
                    help="only this file's rows solved by a commit starting with PREFIX measure the machines")
    args = ap.parse_args(argv)
    cases, runs, planned, started = load(args.results)
    rows, per_n, count = cost(cases, runs)
    print(f"{'N':>5s} {'commit':10s} {'converged':>9s} {'failed':>6s} {'core-h':>8s} {'median pairs':>12s}")
    for N, commit, ok, bad, hours, pairs in rows:
        print(f"{N:5d} {commit:10s} {ok:9d} {bad:6d} {hours:8.2f} {pairs:12.1f}")
    print("planned cases per N: " + ", ".join(f"{N}: {n}" for N, n in sorted(planned.items())))
    complete = count.get(args.n, 0) == planned.get(args.n, -1)
    out = dict(core_hours=per_n, cases=count, planned=planned, n=args.n,
               core_hours_n=per_n.get(args.n) if complete else None, paced=paced(cases))
    for N, p in sorted(out["paced"].items()):
        if p is None:
            print(f"{N:5d}: no pace probe in every converged case (raw_pair_seconds: files before session 43)")
        else:
            print(f"{N:5d}: raw pair (median of the cases' probes) {p['raw_pair'] * 1e3:.1f} ms; time per pair "
                  f"{p['time_per_pair']:.3f} x the raw pair; {p['raw_pair_units']:.0f} core-seconds in raw "
                  f"pairs (core-hours at a raw pair of P seconds: {p['raw_pair_units'] / 3600:.1f} P)")
    if args.reference:
        ref = load(args.reference)[0]
        machine = None
        if args.machine_commit:
            machine = np.array([runs.get(int(r), "?").startswith(args.machine_commit) for r in cases["run"]])
        n, points, mu, sums, by_run = compare(cases, ref, machine)
        print(f"against {args.reference}: {n} cases in both, max |dA| {points:.0f} points, max |dmu|/mu {mu:.1e}")
        print(f"{'N':>5s} {'v (m/s)':>8s} {'cases':>5s} {'pairs':>9s} {'ref pairs':>9s} {'ratio':>6s} "
              f"{'core-h':>7s} {'ref core-h':>10s} {'ratio':>6s}")
        for (N, v), s in sorted(sums.items()):
            print(f"{N:5d} {v:8g} {int(s[0]):5d} {s[1]:9.1f} {s[2]:9.1f} {s[1] / s[2]:6.3f} "
                  f"{s[3] / 3600:7.3f} {s[4] / 3600:10.3f} {s[3] / s[4]:6.3f}")
        rat = ratios(sums, by_run, per_run=not args.machine_commit)
        print("per run of this file (machine: its same-path cases' time over the reference's):")
        print(f"{'N':>5s} {'run':>4s} {'commit':10s} {'started':25s} {'cases':>5s} {'pairs':>6s} "
              f"{'core-h':>6s} {'same-path':>9s} {'machine':>7s}")
        for N, r in sorted(rat.items()):
            for run, q in r["runs"].items():
                m = "n/a" if q["machine"] is None else f"{q['machine']:.3f}"
                print(f"{N:5d} {run:4d} {runs.get(run, '?'):10s} {started.get(run, '?'):25s} {q['cases']:5d} "
                      f"{q['pairs']:6.3f} {q['core_hours']:6.3f} {q['same_path']:9d} {m:>7s}")
        for N, r in sorted(rat.items()):
            if r["machine"] is not None:
                print(f"{N:5d}: same-path cases (equal FFT pairs) took {r['machine']:.3f}x the reference's time")
            if r["core_hours_same_machine"] is not None:
                how = "the --machine-commit rows' ratio" if args.machine_commit else "each run by its own machine ratio"
                print(f"{N:5d}: at the reference's speed ({how}) the core-hours ratio is "
                      f"{r['core_hours_same_machine']:.3f}")
            if r["paced"] is not None:
                print(f"{N:5d}: {r['probed']} cases probed in both: core-seconds in raw pairs, this file over "
                      f"the reference's: {r['paced']:.3f} (the code's cost ratio, each case's machine pace divided out)")
        out.update(compared=n, max_points=points, max_mu_rel=mu, ratios=rat)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
