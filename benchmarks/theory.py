"""Benchmark: Persson's theory on the paper's grid (4 q1 x 4 v x 50 pressures), single core.

Run from the repository root: ``python benchmarks/theory.py``. Prints a table (q1, v, the A/A0 and
mu ranges) and, as the last line, ``{"seconds": S}``: the best-of-REPEATS wall time for the grid.
"""
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import paper_case  # noqa: E402  (benchmarks/: the study's spectra and compound)
from vecontact.cases import spectrum_for  # noqa: E402
from vecontact.physics.theory import persson  # noqa: E402

PRESSURES = np.geomspace(1e3, 1e7, 50)                        # Pa: A/A0 ~0.5 %..60 % on every curve
REPEATS = 5


def run_grid():
    """[(q1/q0, Persson's result at the job's velocities and PRESSURES)] for each q1 of jobs/paper.yaml."""
    job = paper_case.job()
    s, velocities = job.surface, np.asarray(job.sweep.velocity, dtype=float)
    modulus = paper_case.compound()
    return [(round(q1 / s.q0), velocities, persson(spectrum_for(job, q1), modulus, velocities, PRESSURES))
            for q1 in s.q1]


def main():
    best = float("inf")
    for _ in range(REPEATS):
        start = time.perf_counter()
        results = run_grid()
        best = min(best, time.perf_counter() - start)
    print(f"pressures: {len(PRESSURES)} log-spaced, {PRESSURES[0]:.3g}..{PRESSURES[-1]:.3g} Pa; "
          f"{paper_case.compound().describe()}")
    print(f"{'q1/q0':>6} {'v (m/s)':>8} {'A/A0 min':>10} {'A/A0 max':>10} {'mu min':>10} {'mu max':>10}"
          f" {'xi':>8} {'nodes':>6}")
    for k, velocities, res in results:
        for i, v in enumerate(velocities):
            print(f"{k:>6d} {v:>8g} {res.area[i].min():>10.4g} {res.area[i].max():>10.4g} "
                  f"{res.mu[i].min():>10.4g} {res.mu[i].max():>10.4g} {res.xi[i]:>8.4g} {res.q.size:>6d}")
    print(json.dumps({"seconds": round(best, 6)}))


if __name__ == "__main__":
    main()
