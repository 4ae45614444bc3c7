"""The directions an exact contact-set step carries over from the step before it (carry.py).

* the Arnoldi relation a flexible SingleGMRES leaves behind (``arnoldi``): A Z[j] = sum_i G[i, j] V[i]
  to float32 rounding, with restarts and with rows rescaled by powers of two;
* the solver on a paper surface at 10 m/s, ``-vc_carry_map_cost 0`` against ``-vc_carry_directions 0``: the same Newton
  path and answer, the exact step started from the carried directions and took fewer Krylov
  iterations and FFT pairs;
* above ``-vc_carry_area_max``, and below ``-vc_carry_modulus_min``, the contact-set steps carry nothing:
  the path of ``-vc_carry_directions 0``.

The paper case at 256^2 and 10 m/s has a modulus range of 82, under carry_modulus_min's default (100):
the tests of the carry itself open that gate (``CARRY_OPEN``).
"""
import numpy as np
import pytest

from reference.cases import CARRY_OPEN, paper_contact_solve
from reference.krylov import allsum as _allsum, operators as _ops, system as _system

from vecontact.solver.single import SingleGMRES



def _flexible_solve(A, B, b, restart, rtol, work=np.float64):
    gm = SingleGMRES(b.size, restart, _allsum, flexible=True, work=work)
    x = np.empty(b.size)
    its, _ = gm.solve(*_ops(A, B), b, x, rtol, 0.0, 500)
    return gm, its, x


@pytest.mark.parametrize("restart, scale", [(100, 1.0), (7, 1.0), (100, 2.0 ** 40)])
def test_arnoldi_relation(restart, scale):
    """scale 2^40: the rows' lengths leave 2^+-32, so rows are rescaled (single._RANGE), which G must
    follow; restart 7: the relation is the last cycle's."""
    A, B, b = _system(200, 7, scale)
    gm, its, _ = _flexible_solve(A, B, b, restart, 1e-5)
    k, G = gm.arnoldi
    assert k == (its - 1) % restart + 1 and G.shape == (k + 1, k)
    if scale > 1:
        assert gm.rescales > 0
    AZ = gm.Z[:k].astype(np.float64) @ A.T               # rows A Z[j]
    VG = G.T @ gm.V[:k + 1].astype(np.float64)           # rows sum_i G[i, j] V[i]
    for j in range(k):
        # the basis is float32: the relation holds to its rounding (~6e-8 of the product's size)
        assert np.linalg.norm(AZ[j] - VG[j]) <= 1e-5 * np.linalg.norm(AZ[j]), j
    # without a preconditioner's memory (GMRES, not FGMRES) nothing is recorded
    plain = SingleGMRES(b.size, restart, _allsum, flexible=False)
    plain.solve(*_ops(A, B), b, np.empty(b.size), 1e-3, 0.0, 50)
    assert plain.arnoldi is None


@pytest.mark.parametrize("exact", [{}, {"vc_single_exact_reduction_max": "0"}])
def test_exact_step_carries_the_last_steps_directions(exact):
    """A/A0 ~ 7.6 % at 10 m/s: contact-set steps, whose exact step follows a float32 FGMRES step on the
    same set and must cut its residual by less than mixed_reduction_max (the float32 products); the
    exact step in float32 FGMRES (single.py, the default) or in PETSc's (carry.py: ``exact`` 0)."""
    # the changing steps as without carrying (no map)
    on, act_on = paper_contact_solve(dict(CARRY_OPEN, **exact, vc_carry_map_cost="0"))
    off, act_off = paper_contact_solve(dict(CARRY_OPEN, **exact, vc_carry_directions="0"))
    d_on, d_off = on.diagnostics, off.diagnostics
    assert on.converged and off.converged and max(on.residual, off.residual) <= 1e-8
    assert d_on["step_modes"][-1][1] == "contact"
    assert d_on["carried_directions"] > 0 and d_off["carried_directions"] == 0
    # the same Newton path up to the exact step, which only starts from more (without the carry, a
    # float32 exact step may stop on its 2-norm atol just short of the measure: one more exact step)
    n = len(d_on["active_set_changes"])
    assert d_on["active_set_changes"] == d_off["active_set_changes"][:n]
    assert d_on["linear_history"][:-1] == d_off["linear_history"][:n]
    differ = int(np.count_nonzero(act_on != act_off))     # points on the contact line may fall either way
    assert differ <= 4, differ
    assert abs(on.mu / off.mu - 1) <= 1e-6, (on.mu, off.mu)
    # the carried directions cost no FFT pair and are not counted as iterations
    assert on.linear_iterations < off.linear_iterations and on.fft_pairs < off.fft_pairs


@pytest.mark.parametrize("gate", [dict(CARRY_OPEN, vc_carry_area_max="0.05"), {"vc_carry_modulus_min": "83"}],
                         ids=["area", "modulus"])
def test_no_carry_outside_the_gates(gate):
    """The same case (A/A0 7.6 %, modulus range 82.1) with carry_area_max below its A/A0, or
    carry_modulus_min above its range: the contact-set steps neither keep nor start from directions,
    the solve of carry_directions 0 to the FFT pair; inside both gates (0.3, 50) they carry."""
    gated, act_gated = paper_contact_solve(gate)
    off, act_off = paper_contact_solve(dict(gate, vc_carry_directions="0"))    # the gate's other options
    on, _ = paper_contact_solve(CARRY_OPEN)
    assert gated.converged and off.converged and max(gated.residual, off.residual) <= 1e-8
    assert gated.diagnostics["step_modes"][-1][1] == "contact" and 0.05 < gated.area <= 0.3
    assert gated.diagnostics["carried_directions"] == 0 < on.diagnostics["carried_directions"]
    assert gated.diagnostics["linear_history"] == off.diagnostics["linear_history"]
    assert gated.fft_pairs == off.fft_pairs and np.array_equal(act_gated, act_off)
    assert abs(gated.mu / off.mu - 1) <= 1e-12, (gated.mu, off.mu)
