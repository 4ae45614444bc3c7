"""The measure stop of exact Newton steps (vecontact/solver/measurestop.py).

An exact step (the active set stopped changing) may end its Krylov solve as soon as the next Newton
iterate meets the SNES's own convergence test.  The contract checked here, on paper surfaces with the
viscoelastic modulus at 10 m/s, against the same solve with the stop off (``-vc_measure_stop off``):

* the same answer: both converge below tol; the contact sets differ by at most a few points on the
  contact line (each solve is exact only to tol, 1e-8 of sigma0 in complementarity: a point whose
  pressure and kappa x gap are both below that may fall either way), and mu and A/A0 agree to that;
* never more Krylov iterations, and strictly fewer where the step's 2-norm tolerance is far below
  what the max-norm measure needs (the free-set steps, large A/A0);
* the look that stopped the solve measured exactly the iterate the solver returns (the kept iterate
  is the SNES's next one, so its residual is the look's measure, up to rounding), and every earlier
  look of that step measured more than tol (no stop before the measure says so).
"""
import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, Q0

from vecontact.core.pfft import SlabFFT
from vecontact.core.surface import generate
from vecontact.physics.modulus import HavriliakNegami
from vecontact.physics.spectrum import SelfAffine
from vecontact.solver import solve_contact

TOL = 1e-8


def _solve(N, v, sigma0, stop, comm=MPI.COMM_SELF):
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    h = generate(fft, L_PAPER, SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28), 1)
    hn = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    r = solve_contact(fft, L_PAPER, h, hn, v, sigma0, tolerance=TOL, store=("pressure",),
                      petsc_options={"vc_measure_stop": stop})
    return r, fft.gather(r.pressure > 0)


def _exact_step_iterations(r):
    """Krylov iterations of the last Newton step (the exact one that converged)."""
    return int(np.diff(r.diagnostics["linear_history"])[-1])


# (N, v, sigma0, mode of the exact step, fewer iterations asserted)
CASES = [(256, 10.0, 1.0e6, "free", True),      # A/A0 ~ 0.5: free-set steps
         (256, 10.0, 1.0e5, "contact", False)]  # A/A0 ~ 0.05: contact-set steps


@pytest.mark.parametrize("N, v, sigma0, mode, fewer", CASES)
def test_measure_stop_same_solution_fewer_iterations(N, v, sigma0, mode, fewer):
    on, act_on = _solve(N, v, sigma0, "on")
    off, act_off = _solve(N, v, sigma0, "off")
    assert on.converged and off.converged and on.residual <= TOL and off.residual <= TOL
    assert on.diagnostics["step_modes"][-1][1] == mode, on.diagnostics["step_modes"]
    differ = int(np.count_nonzero(act_on != act_off))
    assert differ <= 4, differ
    assert abs(on.area - off.area) <= differ / N ** 2
    assert abs(on.mu / off.mu - 1) <= 1e-6, (on.mu, off.mu)
    # the iterates agree up to the last step; the stop only ends that step's solve earlier
    assert on.diagnostics["active_set_changes"] == off.diagnostics["active_set_changes"]
    assert on.linear_iterations <= off.linear_iterations
    if fewer:
        assert _exact_step_iterations(on) < _exact_step_iterations(off), (on.diagnostics, off.diagnostics)
    looks = on.diagnostics["measure_checks"]
    assert off.diagnostics["measure_checks"] == []
    if looks:
        its, _, measure = looks[-1]
        assert measure <= TOL and on.residual == pytest.approx(measure, rel=1e-9, abs=1e-14)
        assert its == _exact_step_iterations(on)
        earlier = [m for i, _, m in looks[:-1] if i < its]
        assert all(m > TOL for m in earlier), looks
    if fewer:
        assert looks


def test_measure_stop_option_is_checked():
    from vecontact.solver.settings import SolverSettings
    assert SolverSettings().with_options({"vc_measure_stop": "off"}).measure_stop == "off"
    with pytest.raises(ValueError, match="measure_stop"):
        SolverSettings().with_options({"vc_measure_stop": "maybe"})
