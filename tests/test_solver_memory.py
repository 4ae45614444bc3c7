"""What a solve holds in numpy arrays per grid point, against the inventory of its arrays.

The farm sizes ranks per case by the solver's memory (farm/memory.py), and a 4096^2 case on one rank
holds 16.8 million points: every whole-grid float64 array is 134 MB there.  The inventory during the
fine grid's Newton iterations (bytes per grid point; a complex half-spectrum array is 8):

* the operator: m, c, the surface's spectrum, h^ and p_h (40), and its scratch for the measures and
  the active set (8: ContactOperator.work, in place of the temporaries those passes made each call);
* the Newton state: g, p and the active set (17), and the start gap the caller passed (8);
* the steps' one Workspace, shared by both step types: the product's buffer and result and the
  right-hand side work (24), on the contact set also update's s (8) and, where the stiffness's range
  lets the contact set's FGMRES precondition in float32, the float32 Grid (8) and m in float32 (4);
* the measure stop's g and p (16, made at its first look); the step's index arrays (8 per point of its
  set), and the scratch through which a product's input takes the 1/N^2 (subset.Grid.product_of; 8 per
  point of the contact set);
* on the contact set, the preconditioner's edge term (edge.py): its sparse rows S (12 bytes an entry),
  the correction rows of the window masks met so far, a copy of the set and two C-vectors (the
  halo-extended input and, since session 69, the product ``add_to`` keeps with the set, both 5 %
  longer: store_headroom): 18 here, in proportion to the set's edge points.

That is 114 (free-set steps, A/A0 0.88) and 153 (contact-set steps, A/A0 0.19).  Before session 37
each step type had its own buffers, m / kappa and kappa c were kept as arrays (three of them), the
dimensional M and |q| as well, the coarse levels' operators stayed alive through the fine solve (FFTW's
plans held the last arrays they ran on: SlabFFT.release_arrays), and the result was copied out of the
Newton state: 211 and 226 bytes a point here (measured), and 6.0 against 4.5 GB at 4096^2 on one rank
(benchmarks/RESULTS.md, "Memory per grid point").

The Krylov bases are left out: ``-vc_changing_precision double -vc_cycle_precision double`` puts them in
PETSc's Vecs, which tracemalloc does not see (their size is the budgets' business, farm/memory.py), and
``-vc_mixed_reduction_max 0`` keeps the PETSc steps' products in float64, so float64 throughout holds no
float32 Grid unless the contact set's preconditioner asks for it (with mixed PETSc steps it always holds
one: 8 more, and the float32 twin's buffers).
"""
import tracemalloc

import pytest

from reference.cases import L_PAPER, paper_case
from vecontact.solver import solve_contact

N = 256
DOUBLE_KRYLOV = ("-vc_changing_precision double -vc_cycle_precision double -vc_mixed_reduction_max 0 "
                 "-vc_single_exact_reduction_max 0")


@pytest.mark.parametrize("sigma0, mode, area, bound", [(3e5, "contact", 0.194, 160.0), (2e6, "free", 0.881, 123.0)])
def test_a_solve_holds_its_inventory_of_arrays(sigma0, mode, area, bound):
    """Traced numpy memory at every Newton iteration of the fine grid, over what was held before the
    call, per grid point: at most the inventory above plus 9 bytes (the small arrays of N-length rows
    and the coarse levels' sets), so one more whole-grid float64 array (8) fails; measured 156.6 and
    116.2 (154.9 and 116.4 before session 69's kept edge product; the contact case 138.8 until session
    64: with coarse_tol 0.1 its exact step ended on the 2-norm cap before the measure stop's first
    look, which makes its g and p; 130 and 108 before the measures' scratch, 226 and 211 before
    session 37's changes).  A first solve makes the caches (coarse SlabFFTs, the float32 twin)
    outside the measurement."""
    fft, h, modulus = paper_case(N)
    solve_contact(fft, L_PAPER, h, modulus, 10.0, sigma0, tolerance=1e-4, petsc_options=DOUBLE_KRYLOV)
    held = []

    def monitor(level, iteration, residual):
        if level == N:
            held.append(tracemalloc.get_traced_memory()[0])

    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        r = solve_contact(fft, L_PAPER, h, modulus, 10.0, sigma0, tolerance=1e-8, petsc_options=DOUBLE_KRYLOV,
                          store=("pressure",), monitor=monitor)
    finally:
        tracemalloc.stop()
    assert r.converged and r.area == pytest.approx(area, abs=1e-3)
    assert r.diagnostics["step_modes"][0][1] == mode
    per_point = (max(held) - before) / float(N * N)
    assert 60.0 < per_point <= bound, per_point
