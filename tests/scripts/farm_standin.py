"""A tiny stand-in for the surface generator and the contact solver, for the task-farm tests only.

Used when the real ``vecontact.core.surface`` / ``vecontact.solver.solve_contact`` are not importable
(or when VECONTACT_FARM_STANDIN=1). It mimics their interfaces and their collective behaviour:
rank-independent surfaces, global reductions over the FFT's communicator, warm starts that
change the iteration count but not the answer (to the tolerance), optional sleep per case.
"""
import os
import sys
import time
import types

import numpy as np


def generate(fft, L, psd, seed, amplitudes="fixed"):
    rng = np.random.default_rng(int(seed) + 1000 * fft.N)
    full = rng.standard_normal((fft.N, fft.N)) * 1e-8
    return np.ascontiguousarray(full[fft.row_start:fft.row_stop])


def load(fft, path, dataset=None):
    full = np.load(path)
    return np.ascontiguousarray(full[fft.row_start:fft.row_stop])


def solve_contact(fft, L, h, modulus, velocity, sigma0, *, tolerance=1e-8, method="snes",
                  petsc_options=None, warm=None, coarse=True, max_iterations=None,
                  store=("pressure", "gap", "displacement")):
    """'Contact' of a bed of springs: find t with k mean(max(h - t, 0)) = sigma0 by bisection."""
    from vecontact.solver.result import ContactResult
    t0 = time.perf_counter()
    k = 1e13 * (1.0 + 0.1 * np.log1p(velocity))
    from mpi4py import MPI
    hi = 10.0 * fft.comm.allreduce(float(np.max(np.abs(h))), op=MPI.MAX)
    lo = -hi
    if warm is not None:  # more pressure than last time: the plane is below the previous one
        hi = warm.diagnostics["t"]
    it = 0
    n2 = float(fft.N) ** 2
    while True:
        it += 1
        t = 0.5 * (lo + hi)
        f = k * fft.sum(np.maximum(h - t, 0.0)) / n2 - sigma0
        if f > 0:
            lo = t
        else:
            hi = t
        if hi - lo < tolerance * 1e-9 or it > 200 or (max_iterations and it >= max_iterations):
            break
    t = 0.5 * (lo + hi)
    p = k * np.maximum(h - t, 0.0)
    area = fft.sum((p > 0).astype(float)) / n2
    mu = 0.1 * area + 1e-3 * np.log1p(velocity)
    delay = float(os.environ.get("VECONTACT_STANDIN_SLEEP", "0"))
    if delay:
        time.sleep(delay * (fft.N / 64.0) ** 2 / fft.comm.size)
    converged = hi - lo < tolerance * 1e-9
    return ContactResult(area=area, mu=mu, mu_geometric=mu, mean_gap=fft.sum(np.maximum(t - h, 0)) / n2,
                         rigid_position=t, converged=converged, iterations=it, linear_iterations=0,
                         fft_pairs=float(it), residual=(hi - lo) if converged else 1.0,
                         seconds=time.perf_counter() - t0, reason="bisection" if converged else "stand-in: forced",
                         method=method, pressure=p if "pressure" in store else None,
                         gap=np.maximum(t - h, 0) if "gap" in store else None,
                         displacement=(t - h) if "displacement" in store else None,
                         diagnostics={"t": t}, sigma0=sigma0, velocity=velocity, N=fft.N, L=L)


def real_available():
    try:
        import vecontact.core.surface  # noqa: F401
        from vecontact.solver import solve_contact  # noqa: F401
        return True
    except ImportError:
        return False


def install(force=False):
    """Install the stand-in unless the real modules are importable (or ``force``)."""
    if not force and real_available():
        return False
    import vecontact.core
    import vecontact.solver
    mod = types.ModuleType("vecontact.core.surface")
    mod.generate, mod.load = generate, load
    sys.modules["vecontact.core.surface"] = mod
    vecontact.core.surface = mod
    vecontact.solver.solve_contact = solve_contact
    return True
