"""Contact solver vs the dense direct reference on small random rough surfaces (N = 24, 32, 48).

The dense reference (tests/reference/dense.py) builds the N^2 x N^2 compliance matrix from the
Fourier definition and solves the LCP exactly by an active-set method; the solution of the discrete
problem is unique (the symmetric part of the compliance is positive definite), so the solver must
reproduce it up to its own tolerance (1e-8 on complementarity), whatever the method:

* contact set: |dA| <= 1/N^2 (one borderline point; plus the reference's count of degenerate
  points with p ~ 0 and g ~ 0, which is 0 in all cases here);
* pressure: max norm 1e-6 sigma0; gap and displacement (up to its constant): 1e-6 h_rms;
* mu and mu_geometric: 1e-5 relative (they are quadratic/linear in the fields; 1e-6 field errors
  give <= ~1e-6, a factor 10 margin);
* elastic: mu = 0 (no E''), mu_geometric (discretisation-sized, ~1e-5) to 1e-6 rms slope.

Spectrum: q0 = 2 pi / L, qr = 2 q0, q1 = N/6 q0, H = 0.8, C0 = 1e-28 m^4 (h_rms ~ 12 nm); HN
modulus (E0 = 3 MPa, Einf = 3 GPa, alpha = beta = 0.5, tau = 1e-10 s) at v = 1 and 30 m/s
(q v tau ~ 1e-4..1e-2: E'' > E0, well inside the loss region), loads giving A/A0 ~ 10-45%.
"""
import functools

import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, assert_contact_solution, make_fft, rms_slope, small_spectrum, solve_full
from reference.dense import dense_solve, random_surface

from vecontact.physics.modulus import Elastic, HavriliakNegami


def modulus(name):
    if name == "elastic":
        return Elastic(3e6, NU)
    return HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)


# (N, modulus, v, sigma0): dense A/A0 in brackets
CASES = [
    (24, "hn", 1.0, 2e4),        # 0.38
    (24, "hn", 30.0, 2e4),       # 0.10
    (24, "hn", 30.0, 1e5),       # 0.40
    (24, "elastic", 0.0, 3e3),
    (32, "hn", 1.0, 2e4),        # 0.30
    (32, "hn", 30.0, 5e4),
    (32, "elastic", 0.0, 5e3),
    (48, "hn", 30.0, 4e4),
    (48, "hn", 1.0, 2e4),
    (48, "elastic", 0.0, 4e3),
]


def surface(N):
    return random_surface(N, L_PAPER, small_spectrum(N), seed=N)


@functools.lru_cache(maxsize=None)
def reference(N, name, v, sigma0):
    ref = dense_solve(surface(N), L_PAPER, modulus(name), v, sigma0)
    assert ref.min_gap >= -1e-10 and ref.n_degenerate == 0
    return ref


def compare(res, f, ref, h, sigma0, name, label):
    N = h.shape[0]
    hrms = float(np.std(h))
    assert_contact_solution(res, f, h, sigma0)
    assert 0.05 <= ref.area <= 0.6, (label, ref.area)          # the case is a partial contact
    dA = abs(res.area - ref.area) * N * N
    assert dA <= 1 + ref.n_degenerate, (label, res.area, ref.area, dA)
    dp = np.abs(f["pressure"] - ref.pressure).max() / sigma0
    assert dp <= 1e-6, (label, "pressure", dp)
    dg = np.abs(f["gap"] - ref.gap).max() / hrms
    assert dg <= 1e-6, (label, "gap", dg)
    if f["displacement"] is not None:
        w = f["displacement"] - f["displacement"].mean()
        dw = np.abs(w - ref.displacement).max() / hrms
        assert dw <= 1e-6, (label, "displacement", dw)
    assert abs(res.mean_gap - ref.mean_gap) <= 1e-6 * hrms, (label, res.mean_gap, ref.mean_gap)
    if name == "elastic":
        assert abs(res.mu) <= 1e-14, (label, res.mu)
        assert abs(res.mu_geometric - ref.mu_geometric) <= 1e-6 * rms_slope(h, L_PAPER), (
            label, res.mu_geometric, ref.mu_geometric)
    else:
        assert ref.mu > 1e-3
        assert abs(res.mu / ref.mu - 1) <= 1e-5, (label, "mu", res.mu, ref.mu, "literal-E'' formula:", ref.mu_literal)
        assert abs(res.mu_geometric / ref.mu_geometric - 1) <= 1e-5, (
            label, "mu_geometric", res.mu_geometric, ref.mu_geometric)


@pytest.mark.parametrize("N,name,v,sigma0", CASES)
def test_snes_vs_dense(N, name, v, sigma0):
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, comm=MPI.COMM_SELF, method="snes")
    compare(res, f, ref, h, sigma0, name, f"snes N={N} {name} v={v} sigma0={sigma0}")


@pytest.mark.parametrize("N,name,v,sigma0", [c for c in CASES if c[1] == "elastic"])
def test_pk_vs_dense_elastic(N, name, v, sigma0):
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, comm=MPI.COMM_SELF, method="pk")
    compare(res, f, ref, h, sigma0, name, f"pk N={N} sigma0={sigma0}")


def test_snes_vs_dense_cold_start():
    """Same case without the coarse-grid warm start (coarse=False) still converges to the exact solution."""
    N, name, v, sigma0 = 32, "hn", 30.0, 5e4
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, comm=MPI.COMM_SELF, coarse=False)
    compare(res, f, ref, h, sigma0, name, "snes cold")


def test_warm_start_from_other_load():
    """A warm start from the solution at another load gives the same exact solution."""
    N, name, v, sigma0 = 32, "hn", 1.0, 2e4
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    fft = make_fft(MPI.COMM_SELF, N)
    first, _ = solve_full(h, L_PAPER, modulus(name), v, 5e4, fft=fft)
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, fft=fft, warm=first)
    compare(res, f, ref, h, sigma0, name, "snes warm")


# cycles: caps of 3 iterations, so the first step uses its cap and the cycles start (StepPolicy.cycling),
# by cycle_after_cap, or by cycle_after_cap_large where the operator's stiffness range exceeds
# cycle_range_max (0: every grid's)
_CAP = {"vc_lin_maxit_changing": 3, "vc_cycle_after_cap": 3, "vc_cycle_range_max": 1e12}
_RANGE = {"vc_lin_maxit_changing": 3, "vc_cycle_after_cap": 1000, "vc_cycle_after_cap_large": 3,
          "vc_cycle_range_max": 0}


@pytest.mark.parametrize("step, cycle, gate", [("contact", 0, {}), ("free", 0, {}), ("free", 0, {"vc_step_sweeps": 0}),
                                               ("free", 4, _CAP), ("free", 4, _RANGE)],
                         ids=["contact", "free", "free-unsmoothed", "cycles", "range"])
@pytest.mark.parametrize("v,sigma0", [(1.0, 2e4), (30.0, 5e4)])
def test_newton_step_modes_vs_dense(step, cycle, gate, v, sigma0):
    """Both ways of solving the Newton step (on the contact set / on the free set, chosen by area in
    ``auto``; the free set by plain GMRES, or by FGMRES over GMRES(4) cycles once a step used its cap)
    forced for a whole solve: the same exact solution; with the free set's smoothing after every changing
    step (SolverSettings.step_sweeps) or without it."""
    N, name = 32, "hn"
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    opts = {"vc_contact_step": step, "vc_free_cycle": cycle, **gate}
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, comm=MPI.COMM_SELF, coarse=False,
                        petsc_options=opts)
    compare(res, f, ref, h, sigma0, name, f"snes step={step} v={v}")
    changing = sum(1 for c in res.diagnostics["active_set_changes"] if c != 0)
    smoothed = changing if step == "free" and gate.get("vc_step_sweeps", 1) else 0
    assert changing > 0 and res.diagnostics["smoothed_steps"] == smoothed
    if cycle:   # the steps after the first ran in whole cycles of 4
        its = np.diff(res.diagnostics["linear_history"])
        assert its[0] == 3 and len(its) > 1 and np.all(its[1:] % cycle == 0), its


@pytest.mark.parametrize("N,name,v,sigma0", [(32, "hn", 1.0, 2e4), (32, "hn", 30.0, 5e4),
                                             (32, "elastic", 0.0, 5e3)])
def test_vi_vs_dense(N, name, v, sigma0):
    """PETSc's reduced-space VI Newton method (-snes_type vinewtonrsls, vecontact/solver/vi.py), the
    alternative to the default: the same exact solution."""
    h = surface(N)
    ref = reference(N, name, v, sigma0)
    res, f = solve_full(h, L_PAPER, modulus(name), v, sigma0, comm=MPI.COMM_SELF,
                        petsc_options={"snes_type": "vinewtonrsls"})
    assert res.diagnostics["step_modes"] == [] and res.diagnostics["active_set_changes"] == []
    compare(res, f, ref, h, sigma0, name, f"vinewtonrsls {name} v={v}")
