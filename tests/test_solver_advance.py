"""The pressure of the next Newton iterate after a contact-set step, without an FFT pair
(NewtonState.advance, contactset.py).

A contact-set step returns the update x = c s + e with its pressure increment s (e a rigid shift), so
the next iterate g - x has the pressure p - (s - mean s): m has no q = 0 mode.  Checked against the
pressure computed with a pair, and in whole solves against the same solves with advance turned off.
"""
import numpy as np
import pytest
from test_solver_measurestop import _solve
from test_solver_steps import _apply_step, _operator

from vecontact.solver.contactset import ContactSetStep
from vecontact.solver.newton import NewtonState
from vecontact.solver.settings import SolverSettings
from vecontact.solver.snes import petsc


def test_advance_gives_the_pressure_of_the_next_iterate():
    """One contact-set step solved tightly from a random gap: the advanced (g, p) is g - x and
    p^(g - x) to rounding (1e-12 of max|p|: a few FFT roundings of O(max|p|) values; a sign error fails
    by O(1)), also from an s with a mean (m x has none: without the mean's removal it fails by 0.25), the
    SNES's next residual then costs no transform, and a second advance, or one after keep(), changes
    nothing."""
    op = _operator()
    fft = op.fft
    rng = np.random.default_rng(3)
    g = np.abs(rng.standard_normal(fft.local_real_shape)) * (op.hhat < np.quantile(op.hhat, 0.9))
    state = NewtonState(op)
    state.ensure(g)
    state.update_active_set()
    assert 0 < state.nact < g.size
    step = ContactSetStep(op, op.kappa, petsc(), "advtest_", SolverSettings())
    step.advance = state.advance
    try:
        step.set_tolerances(1e-13, 0.0, 500)
        r = np.minimum(g, state.p / op.kappa)                      # F(g): the Newton right-hand side
        x = _apply_step(step, state.act, r)
    finally:
        step.release()
    nxt = g - x
    assert np.array_equal(state.g, nxt)
    exact = op.pressure(nxt)
    scale = np.max(np.abs(exact))
    assert np.max(np.abs(state.p - exact)) <= 1e-12 * scale
    assert abs(fft.mean(state.p) - 1.0) <= 1e-12 * scale            # the load: mean p^ = 1
    t0 = fft.transforms
    state.ensure(nxt)
    assert fft.transforms == t0
    p = state.p.copy()
    state.advance(x, x)                                            # not at the Jacobian's iterate: nothing
    assert np.array_equal(state.g, nxt) and np.array_equal(state.p, p)
    # s with a mean: m x has none, so the advance removes it
    state.ensure(g)
    state.update_active_set()
    state.advance(x, fft.apply(x, op.m) + 0.25)
    assert np.max(np.abs(state.p - exact)) <= 1e-12 * scale
    state.update_active_set()
    state.keep(g, op.pressure(g))
    state.advance(x, x)
    assert np.array_equal(state.g, g)


@pytest.mark.parametrize("v, sigma0", [(10.0, 1.0e5), (0.01, 2.0e3)])
def test_contact_set_steps_save_one_pair_each(v, sigma0, monkeypatch):
    """256^2 paper surface, contact-set steps on every grid (A/A0 ~ 7 % and 1.7 %): against the same
    solve with advance off, the same Newton path (set changes, Krylov iterations), the same A/A0 and mu
    to rounding (1e-12), and on the fine grid exactly one FFT pair fewer per Newton step."""
    on, act_on = _solve(256, v, sigma0, "on")
    monkeypatch.setattr(NewtonState, "advance", lambda self, x, s: None)
    off, act_off = _solve(256, v, sigma0, "on")
    assert on.converged and off.converged
    assert on.diagnostics["step_modes"] == [(0, "contact")]
    assert on.diagnostics["active_set_changes"] == off.diagnostics["active_set_changes"]
    assert on.linear_iterations == off.linear_iterations
    assert np.array_equal(act_on, act_off)
    assert on.mu == pytest.approx(off.mu, rel=1e-12)
    assert off.fft_pairs_by_level[256] - on.fft_pairs_by_level[256] == on.iterations


def test_measures_are_their_definitions():
    """ContactOperator.measures (passes in one scratch, operator.py) against the definitions written
    out with temporaries: complementarity max |min(p^, kappa g^)| and penetration max(0, max -g^) bit
    for bit (the same roundings), the force |mean(p^ on C) - 1| to 1e-14 (its sum is ordered
    differently: a few roundings of O(max|p^|) terms over N^2); with the default C = {p^ >= kappa g^}
    and a given one.  The scratch is reused: the inputs are left as they were."""
    op = _operator()
    rng = np.random.default_rng(7)
    g = rng.standard_normal(op.fft.local_real_shape)
    p = 1.0 + rng.standard_normal(op.fft.local_real_shape)
    g0, p0 = g.copy(), p.copy()
    for act in (None, rng.random(g.shape) < 0.3):
        C = p >= op.kappa * g if act is None else act
        comp, pen, force = op.measures(g, p, act)
        assert comp == float(np.abs(np.minimum(p, op.kappa * g)).max())
        assert pen == max(float((-g).max()), 0.0)
        want = abs(float(np.sum(p, where=C)) / g.size - 1.0)
        assert abs(force - want) <= 1e-14 * float(np.abs(p).max())
        assert np.array_equal(g, g0) and np.array_equal(p, p0)
    # no penetration: the measure is 0, not the largest gap's negative
    assert op.measures(np.abs(g) + 0.5, p)[1] == 0.0


def test_smooth_step_replaces_the_step_by_the_smoothed_iterate():
    """NewtonState.smooth_step (the free-set steps' smoothing, snes.py): the step y from x becomes
    x - S(max(x - y, 0)), S the sweeps of warmstart.smooth_gap computed on their own arrays (the same
    operations in the same order, so the same bits), at one FFT pair a sweep; the cached iterate is let
    go of, so the next ensure() computes the pressure of the new one."""
    from vecontact.solver.warmstart import smooth_gap
    op = _operator()
    fft = op.fft
    rng = np.random.default_rng(5)
    x = np.abs(rng.standard_normal(fft.local_real_shape)) * (op.hhat < np.quantile(op.hhat, 0.8))
    y = 0.1 * rng.standard_normal(fft.local_real_shape)
    state = NewtonState(op)
    state.ensure(x)
    expected = x - smooth_gap(op, np.maximum(x - y, 0.0), 3, 6.0)
    y0 = y.copy()
    t0 = fft.transforms
    state.smooth_step(x, y, 3, 6.0)
    assert (fft.transforms - t0) / 2 == 3
    assert np.array_equal(y, expected)
    assert np.max(np.abs(y - y0)) > 1e-3 * np.max(np.abs(y0))           # the sweeps did move the iterate
    assert not state.valid
    t0 = fft.transforms
    state.ensure(x - y)
    assert (fft.transforms - t0) / 2 == 1
    assert np.max(np.abs(state.p - op.pressure(x - y))) <= 1e-12 * np.max(np.abs(state.p))
