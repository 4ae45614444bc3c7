"""Independent reference solutions for validating vecontact's contact solver.

Nothing here imports vecontact's solver or FFT code: the discrete operator of docs/conventions.md
section 4 is rebuilt from its Fourier definition with numpy, and the linear complementarity
problem is solved by a dense direct active-set method (:mod:`reference.dense`). Closed-form
results (Westergaard, Johnson-Greenwood-Higginson, full contact) are in :mod:`reference.analytic`.
"""
