"""Exact solution on a measured topography, compared with Persson's theory for its spectrum.

    python examples/solve_topography.py [SCAN] [VELOCITY]

SCAN is any format SurfaceTopography reads (x3p, sur, datx, opd, plu, gwy, DI ...; install
``vecontact[topography]``), VELOCITY the sliding speed in m/s. The scan is converted to m,
detrended, cropped to a square and made periodic (docs/inputs.md). The same inputs from the command
line: examples/topography_job.yaml.
"""
import os
import sys

import numpy as np

import vecontact as vc

path = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                          "data", "scan.x3p")
velocity = float(sys.argv[2]) if len(sys.argv) > 2 else 0.01          # m/s
s = vc.read_topography(path)
E = vc.modulus(**vc.REFERENCE_COMPOUND)
st = s.statistics()
print(f"{os.path.basename(path)}: {s.info['processing']}")
print(f"N = {s.N}, L = {s.length * 1e6:.2f} um, h_rms = {st['hrms'] * 1e9:.2f} nm, rms slope = {st['slope_rms']:.4f}")
print(f"{'sigma0 (Pa)':>12} {'A/A0 theory':>12} {'A/A0 exact':>11} {'mu theory':>10} {'mu exact':>9}")
result = None
for p in np.geomspace(2e4, 2e5, 4):                                   # rising load: warm starts
    t = vc.theory(s, E, velocity=velocity, pressure=p)
    result = vc.solve(s, E, velocity=velocity, pressure=p, warm=result)
    print(f"{p:12.4g} {t.area:12.4f} {result.area:11.4f} {t.mu:10.5f} {result.mu:9.5f}"
          f"{'' if result.converged else '  (not converged)'}")
