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
way, which measures the two runs' machines; ``core_hours_same_machine``: core_hours / machine).
``--machine-commit PREFIX`` keeps only this file's rows solved by a commit starting with PREFIX in
``machine``: a later code version can take the same path at another speed.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from vecontact.status import read_status  # noqa: E402

KEY = ("q1", "seed", "velocity", "pressure")


def load(path):
    """(/cases structured array, {run index: git commit}, {N: cases the job plans}) of a results file
    (read by :func:`vecontact.status.read_status`)."""
    st = read_status(path)
    runs = {int(r["run"]): str(r.get("git_commit") or "?")[:10] for r in st["runs"]}
    q1s = [q1 for q1, *_ in st["expected"]]
    grids = {q1: st["job"].surface.grid(q1) for q1 in set(q1s)}    # once per q1 (a height file is read)
    planned = {}
    for q1 in q1s:
        planned[grids[q1]] = planned.get(grids[q1], 0) + 1
    return st["cases"], runs, planned


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


SAME_PATH_RTOL = 1e-9   # FFT pairs equal to this: the case took the same path through the solver


def compare(cases, ref, machine=None):
    """Cases converged in both: (count, max |dA/A0| N^2 in points, max relative d mu, sums) with
    sums[(N, velocity)] = array [cases, pairs here, pairs in ref, core-seconds here, core-seconds in ref,
    the same two core-seconds over the cases whose FFT pairs are equal in both files and, if given,
    whose entry of the bool array ``machine`` (aligned with ``cases``) is True]."""
    index = {tuple(float(r[k]) for k in KEY): r for r in ref[ref["converged"] == 1]}
    n, points, mu, sums = 0, 0.0, 0.0, {}
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
        row = np.array([1, r["fft_pairs"], o["fft_pairs"], here, there, here * same, there * same], dtype=float)
        key = (int(r["N"]), float(r["velocity"]))
        sums[key] = sums.get(key, 0.0) + row
    return n, points, mu, sums


def ratios(sums):
    """Per N over every velocity of ``sums`` (compare): ``pairs`` and ``core_hours`` (here / ref),
    ``machine`` (core-seconds here / ref over the same-path cases: the two machines' speed ratio, null
    without such cases) and ``core_hours_same_machine`` (core_hours / machine)."""
    out = {}
    for (N, _), s in sums.items():
        out[N] = out.get(N, 0.0) + s
    res = {}
    for N, t in out.items():
        machine = float(t[5] / t[6]) if t[6] > 0 else None
        res[N] = dict(pairs=float(t[1] / t[2]), core_hours=float(t[3] / t[4]), machine=machine,
                      core_hours_same_machine=float(t[3] / t[4] / machine) if machine else None)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--reference", help="another results file of the same job: cases compared")
    ap.add_argument("--n", type=int, default=4096, help="grid whose total is reported as core_hours_n")
    ap.add_argument("--machine-commit", metavar="PREFIX",
                    help="only this file's rows solved by a commit starting with PREFIX measure the machines")
    args = ap.parse_args(argv)
    cases, runs, planned = load(args.results)
    rows, per_n, count = cost(cases, runs)
    print(f"{'N':>5s} {'commit':10s} {'converged':>9s} {'failed':>6s} {'core-h':>8s} {'median pairs':>12s}")
    for N, commit, ok, bad, hours, pairs in rows:
        print(f"{N:5d} {commit:10s} {ok:9d} {bad:6d} {hours:8.2f} {pairs:12.1f}")
    print("planned cases per N: " + ", ".join(f"{N}: {n}" for N, n in sorted(planned.items())))
    complete = count.get(args.n, 0) == planned.get(args.n, -1)
    out = dict(core_hours=per_n, cases=count, planned=planned, n=args.n,
               core_hours_n=per_n.get(args.n) if complete else None)
    if args.reference:
        ref, _, _ = load(args.reference)
        machine = None
        if args.machine_commit:
            machine = np.array([runs.get(int(r), "?").startswith(args.machine_commit) for r in cases["run"]])
        n, points, mu, sums = compare(cases, ref, machine)
        print(f"against {args.reference}: {n} cases in both, max |dA| {points:.0f} points, max |dmu|/mu {mu:.1e}")
        print(f"{'N':>5s} {'v (m/s)':>8s} {'cases':>5s} {'pairs':>9s} {'ref pairs':>9s} {'ratio':>6s} "
              f"{'core-h':>7s} {'ref core-h':>10s} {'ratio':>6s}")
        for (N, v), s in sorted(sums.items()):
            print(f"{N:5d} {v:8g} {int(s[0]):5d} {s[1]:9.1f} {s[2]:9.1f} {s[1] / s[2]:6.3f} "
                  f"{s[3] / 3600:7.3f} {s[4] / 3600:10.3f} {s[3] / s[4]:6.3f}")
        rat = ratios(sums)
        for N, r in sorted(rat.items()):
            if r["machine"] is not None:
                print(f"{N:5d}: same-path cases (equal FFT pairs) took {r['machine']:.3f}x the reference's "
                      f"time, so at the reference's speed the core-hours ratio is {r['core_hours_same_machine']:.3f}")
        out.update(compared=n, max_points=points, max_mu_rel=mu, ratios=rat)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
