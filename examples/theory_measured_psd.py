"""Persson's theory on a measured power spectrum C(q): real contact area and rubber friction.

    python examples/theory_measured_psd.py [C.csv]

The table holds q (1/m) and C (m^4, Persson's 2-D convention); a line-scan C1D (m^3) is read with
vc.read_psd(path, dimension=1). The same inputs from the command line: examples/psd_job.yaml
(``vecontact run examples/psd_job.yaml``).
"""
import os
import sys

import numpy as np

import vecontact as vc

DEFAULT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "measured_psd.csv")

psd = vc.read_psd(sys.argv[1] if len(sys.argv) > 1 else DEFAULT)   # checked: order, sign, units
E = vc.modulus(**vc.REFERENCE_COMPOUND)                               # or vc.modulus("table", file=...)
print(psd.describe())
pressures = np.geomspace(0.05e6, 1.0e6, 5)                            # Pa
for v in (1e-3, 1e-1, 10.0):                                          # m/s
    t = vc.theory(psd, E, velocity=v, pressure=pressures)
    print(f"v = {v:g} m/s   xi = {t.xi:.4f}")
    for p, area, mu in zip(pressures, t.area, t.mu):
        print(f"  sigma0 = {p:9.3g} Pa   A/A0 = {area:.4f}   mu = {mu:.4f}")
