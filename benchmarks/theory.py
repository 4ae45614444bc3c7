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

from vecontact.physics.modulus import HavriliakNegami  # noqa: E402
from vecontact.physics.spectrum import SelfAffine  # noqa: E402
from vecontact.physics.theory import persson  # noqa: E402

Q0 = 2.5e5                     # 1/m
C0 = 1.0616e-28                # m^4
Q1_OVER_Q0 = (32, 64, 128, 256)
VELOCITIES = np.array([0.01, 0.1, 1.0, 10.0])                 # m/s
PRESSURES = np.geomspace(1e3, 1e7, 50)                        # Pa: A/A0 ~0.5 %..60 % on every curve
REPEATS = 5


def run_grid():
    modulus = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    return [(k, persson(SelfAffine(Q0, 4 * Q0, k * Q0, 0.8, C0), modulus, VELOCITIES, PRESSURES))
            for k in Q1_OVER_Q0]


def main():
    best = float("inf")
    for _ in range(REPEATS):
        start = time.perf_counter()
        results = run_grid()
        best = min(best, time.perf_counter() - start)
    print(f"pressures: {len(PRESSURES)} log-spaced, {PRESSURES[0]:.3g}..{PRESSURES[-1]:.3g} Pa; "
          f"HN compound (E0 3 MPa, Einf 3 GPa, alpha = beta = 0.5, tau 1e-10 s), nu = 0.5")
    print(f"{'q1/q0':>6} {'v (m/s)':>8} {'A/A0 min':>10} {'A/A0 max':>10} {'mu min':>10} {'mu max':>10}"
          f" {'xi':>8} {'nodes':>6}")
    for k, res in results:
        for i, v in enumerate(VELOCITIES):
            print(f"{k:>6d} {v:>8g} {res.area[i].min():>10.4g} {res.area[i].max():>10.4g} "
                  f"{res.mu[i].min():>10.4g} {res.mu[i].max():>10.4g} {res.xi[i]:>8.4g} {res.q.size:>6d}")
    print(json.dumps({"seconds": round(best, 6)}))


if __name__ == "__main__":
    main()
