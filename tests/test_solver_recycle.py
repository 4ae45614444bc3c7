"""Krylov recycling across contact-set Newton steps (vecontact/solver/contactset.py, _Recycler).

The recycler maps the directions z of earlier inner solves to a new contact set without FFTs: its image
A' u (A' = P c_C'C', u = z restricted to C', mean removed) is rebuilt from the stored fields c z, the
real-space kernel of c for the points that left the set, and a combination that removes the means.
Every row u of the recycle space must therefore satisfy A' u = w (its row of W) to rounding: checked
against the FFT application of A' to 1e-10 of |w| (the dense kernel products sum ~N^2 terms of size
|c z|, double rounding ~1e-13)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import random_surface

from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import HavriliakNegami
from vecontact.solver.contactset import ContactSetStep
from vecontact.solver.operator import ContactOperator
from vecontact.solver.settings import SolverSettings
from vecontact.solver.snes import petsc


def _step(N, v):
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=N)
    op = ContactOperator(fft, L_PAPER, HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU), v, 3e4, h)
    s = SolverSettings(recycle_vectors=30, recycle_cost=1e9)
    return op, ContactSetStep(op, op.kappa, petsc(), "recycletest_", s)


def _solve(step, act, rng):
    """One inner solve on ``act`` (rtol 1e-6) from a random right-hand side: records its directions."""
    PETSc = petsc()
    step.set_active(act, int(act.sum()))
    step.set_tolerances(1e-6, 0.0, 200)
    r = PETSc.Vec().createSeq(act.size)
    r.getArray()[:] = rng.standard_normal(act.size)
    y = r.duplicate()
    step.apply(None, r, y)
    out = y.getArray().copy()
    r.destroy()
    y.destroy()
    return out


@pytest.mark.parametrize("v", [1.0, 30.0])
def test_mapped_space_is_the_image_of_the_new_operator(v):
    N = 32
    op, step = _step(N, v)
    rng = np.random.default_rng(5)
    try:
        act = (op.hhat > 0.3).copy()
        _solve(step, act, rng)
        new = act.copy()
        edge = np.flatnonzero(act.ravel())[::7]
        new.flat[edge] = False                                   # points leave the set
        new.flat[np.flatnonzero(~act.ravel())[::11]] = True      # and others join it
        step.set_active(new, int(new.sum()))
        rc = step.recycler
        rc.prepare(new, step.idx)
        assert rc.U.shape[0] >= 5
        PETSc = petsc()
        x = PETSc.Vec().createSeq(step.idx.size)
        y = x.duplicate()
        for u, w in zip(rc.U, rc.W):
            x.getArray()[:] = u
            step._plain._apply(x, y)
            assert np.abs(y.getArray() - w).max() <= 1e-10 * np.abs(w).max()
        assert np.allclose(rc.W @ rc.W.T, np.eye(rc.W.shape[0]), atol=1e-10)   # orthonormal
        assert np.abs(rc.U.sum(axis=1)).max() <= 1e-10 * np.abs(rc.U).max() * math.sqrt(step.idx.size)
        x.destroy()
        y.destroy()
    finally:
        step.release()


def test_recycled_solve_matches_the_plain_solve():
    """The second solve on a changed set gives the same step (to its rtol) with and without the space,
    and needs fewer iterations with it."""
    N = 32
    rng = np.random.default_rng(2)
    results = []
    for recycle in (0, 30):
        op, step = _step(N, 30.0)
        if recycle == 0:
            step.recycler = None
        try:
            act = (op.hhat > 0.3).copy()
            _solve(step, act, np.random.default_rng(7))
            new = act.copy()
            new.flat[np.flatnonzero(act.ravel())[::13]] = False
            it0 = step.iterations
            y = _solve(step, new, np.random.default_rng(8))
            results.append((y, step.iterations - it0))
        finally:
            step.release()
    (y0, it0), (y1, it1) = results
    assert np.abs(y1 - y0).max() <= 1e-4 * np.abs(y0).max()
    assert it1 < it0
