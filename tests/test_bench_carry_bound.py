"""benchmarks/carry_bound.py: its GCRO solve and the kernel map of carried products to a new free set."""
import json
from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from reference.bench import load
from reference.krylov import system
from vecontact.core.pfft import SlabFFT


@pytest.fixture(scope="module")
def bench():
    return load("carry_bound")


def test_gcro_residual_and_carried_space(bench):
    """The residual GCRO stops on is the true one (to rounding), and the directions of one solve, carried
    into a nearby right-hand side, cut the iterations (24 against 86 here) at the same accuracy."""
    A, B, b = system()
    s = SimpleNamespace(A=lambda x: A @ x, B=lambda z: B @ z)
    its, x, Z = bench.gcro(s, b, 1e-10)
    assert np.linalg.norm(b - s.A(x)) <= 1e-9 * np.linalg.norm(b)
    assert Z.shape == (b.size, its) and 0 < its < b.size
    # carry the first solve's directions into a nearby right-hand side: fewer iterations, same accuracy
    b2 = b + 1e-3 * np.random.default_rng(3).standard_normal(b.size)
    C, R = np.linalg.qr(A @ Z)
    U = np.linalg.solve(R.T, Z.T).T
    its2, x2, _ = bench.gcro(s, b2, 1e-10, U, C)
    assert np.linalg.norm(b2 - s.A(x2)) <= 1e-9 * np.linalg.norm(b2)
    assert its2 < its


def test_kernel_map_exact_for_a_local_kernel(bench):
    """With a multiplier whose kernel is the 5-point stencil (reach 1), a window of rho = 1 maps the
    products of directions to a new set exactly: columns of points that left removed, products at
    points that joined formed."""
    N = 16
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate")
    kx = 2 * np.pi * np.fft.fftfreq(N)
    ky = 2 * np.pi * np.fft.rfftfreq(N)
    lap = 4 - 2 * np.cos(kx)[:, None] - 2 * np.cos(ky)[None, :]
    mult = np.ascontiguousarray(lap[:, fft.col_start:fft.col_stop]).astype(fft.complex_dtype)
    kmap = bench.KernelMap(fft, mult, 0.5, rho=1)

    def products(Z, idx):
        out = []
        for z in Z.T:
            y = fft.apply(z.reshape(N, N).copy(), mult, fft.real_array(), 0.5)
            out.append(y.ravel()[idx])
        return np.stack(out, axis=1)

    rng = np.random.default_rng(4)
    old = np.flatnonzero(rng.random(N * N) < 0.5)
    gone = old[rng.random(old.size) < 0.1]
    new = np.union1d(np.setdiff1d(old, gone), np.flatnonzero(rng.random(N * N) < 0.1))
    Z = np.zeros((N * N, 3))
    Z[old, :] = rng.standard_normal((old.size, 3))
    W = np.zeros_like(Z)
    W[old, :] = products(Z, old)
    mapped, n_left, n_joined = kmap(Z, W, old, new)
    Znew = np.zeros_like(Z)
    Znew[new, :] = Z[new, :]                     # zero where it left, zero where it joined
    assert n_left == np.setdiff1d(old, new).size > 0 and n_joined == np.setdiff1d(new, old).size > 0
    np.testing.assert_allclose(mapped, products(Znew, new), rtol=0, atol=1e-12 * np.abs(W).max())


def test_bound_on_a_real_solve(bench):
    """128², A/A0 39 %: the free-set steps are recorded, float64 GMRES redoes each in about the real
    step's iterations (the changing steps ran a float32 basis: within 2), and GCRO with exact products
    of the carried directions ends at its target with no more iterations in all."""
    result, rows = bench.bound_rows(128, 0.01, 30000.0, [10])
    assert result.converged and 0.3 < result.area < 0.5 and len(rows) >= 2
    for row in rows:
        assert abs(row["plain"] - row["real"]) <= 2
        assert row["K10_residual"] <= row["target"] * (1 + 1e-6)
    assert sum(r["K10"] for r in rows) <= sum(r["plain"] for r in rows)


def test_bound_on_contact_set_steps(bench):
    """128², A/A0 4 %: the contact-set steps are recorded and redone with P c_CC P and the solver's
    preconditioner (m_CC and the edge correction) in float64: about the real steps' iterations (within
    2: the changing steps ran float32, the exact one carried); carried directions reach every target
    with no more iterations in all.  A window map is refused: c's kernel is not local."""
    result, rows = bench.bound_rows(128, 0.01, 3000.0, [10], mode="contact")
    assert result.converged and 0.02 < result.area < 0.06 and len(rows) >= 2
    from vecontact.solver.contactset import ContactSetStep
    assert "solve" not in vars(ContactSetStep)        # the recording left the class as it found it
    for row in rows:
        assert abs(row["plain"] - row["real"]) <= 2 and row["K10_residual"] <= row["target"] * (1 + 1e-6)
    assert sum(r["K10"] for r in rows) <= sum(r["plain"] for r in rows)
    sizes = [r["set"] for r in rows]
    for before, row in zip(sizes, rows[1:]):                  # points that left and joined the set
        assert row["set"] - before == row["changed"][1] - row["changed"][0]
    with pytest.raises(ValueError, match="--window"):
        bench.bound_rows(128, 0.01, 3000.0, [10], window=2, mode="contact")


def test_map_cost_rows(bench, capsys):
    """--map-cost: one row per number of changed points, its units |C| changed / N^2 from the sets it
    made, and the pairs per unit derived from its own timings."""
    assert bench.main(["--map-cost", "--n", "64", "--fraction", "0.1", "--changed", "4,40"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["N"] == 64 and out["K"] > 0 and out["pair_ms"] > 0
    assert [r["changed"] for r in out["rows"]] == [4, 40]
    for r in out["rows"]:
        assert abs(r["units"] - 0.1 * r["changed"]) <= 0.03 * r["changed"]      # |C| ~ 0.1 N^2
        assert r["map_ms"] > 0 and r["pairs"] == pytest.approx(r["map_ms"] / out["pair_ms"], rel=1e-3)
