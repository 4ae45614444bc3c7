"""contactset.oracle_solve, issue #15's yardstick: one Newton step on the final contact set by FGMRES,
unrestarted while its basis fits its memory; a restart only adds iterations, so a restarted oracle
would flatter the Newton loop's ratio to it (benchmarks/RESULTS.md, "The oracle without a restart")."""
import numpy as np

from reference.cases import L_PAPER, paper_case


def test_oracle_runs_unrestarted_and_a_restart_costs_iterations():
    from vecontact.solver import solve_contact
    from vecontact.solver.contactset import oracle_solve
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.settings import SolverSettings
    fft, h, hn = paper_case(256)
    v, sigma0 = 10.0, 1.1e5
    r = solve_contact(fft, L_PAPER, h, hn, v, sigma0, tolerance=1e-8, store=("pressure",))
    act = r.pressure > 0
    n_set = int(np.count_nonzero(act))

    def oracle(memory, krylov="fgmres"):
        return oracle_solve(ContactOperator(fft, L_PAPER, hn, v, sigma0, h), act, 1e-8, 500, SolverSettings(),
                            memory=memory, krylov=krylov)

    full = oracle(6e9)
    assert full["restart"] == 500 and full["converged"] and full["iterations"] < 500
    # every iteration applies c_CC and m_CC: two FFT pairs, plus the set-up's
    assert 2 * full["iterations"] <= full["pairs"] <= 2 * full["iterations"] + 4
    # a basis of 11 vectors' memory (two float64 vectors an iteration): restarted every 10, more iterations
    # (GMRES minimises the residual over its whole Krylov space, a restarted one over less)
    short = oracle(16.0 * n_set * 11)
    assert short["restart"] == 10 and short["converged"]
    assert full["iterations"] > 10 and short["iterations"] > full["iterations"]

    # right-preconditioned GMRES: m_CC is a fixed linear map, so FGMRES's iterations and residual (to
    # rounding: the two orthogonalise different vectors) from one vector an iteration, the solution formed
    # with one more m_CC (one pair); the same memory fits twice the restart
    gm = oracle(6e9, "gmres")
    assert gm["restart"] == 500 and gm["converged"]
    assert abs(gm["iterations"] - full["iterations"]) <= 1
    assert abs(gm["residual"] - full["residual"]) <= 1e-3 * full["residual"]
    assert gm["pairs"] == full["pairs"] + 1 + (gm["iterations"] - full["iterations"]) * 2
    assert oracle(16.0 * n_set * 11, "gmres")["restart"] == 21
    # the choice does not outlive the call: the next FGMRES oracle is FGMRES again
    from vecontact.solver.snes import petsc
    assert not petsc().Options().hasName("oracle_contact_ksp_type")
    assert oracle(6e9)["pairs"] == full["pairs"]


def test_the_matched_oracle_refines_to_the_solvers_own_test():
    """rtol 1e-8 from p^ = 1 leaves the oracle's iterate far short of the solver's tolerance (its measure
    starts near 1e3); the refinement step (``tol``) goes on to the first iterate that meets the solver's
    test, the looks' pairs not counted."""
    from vecontact.solver import solve_contact
    from vecontact.solver.contactset import oracle_solve
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.settings import SolverSettings
    fft, h, hn = paper_case(256)
    v, sigma0, tol = 10.0, 1.1e5, 1e-8
    r = solve_contact(fft, L_PAPER, h, hn, v, sigma0, tolerance=tol, store=("pressure",))
    act = r.pressure > 0
    op = ContactOperator(fft, L_PAPER, hn, v, sigma0, h)
    plain = oracle_solve(op, act, 1e-8, 500, SolverSettings(), memory=6e9)
    both = oracle_solve(op, act, 1e-8, 500, SolverSettings(), memory=6e9, tol=tol)
    # the first solve is the plain oracle, bit for bit
    assert {k: both[k] for k in plain} == plain
    m = both["matched"]
    assert m["converged"] and m["measure"] <= tol < 1e3 * tol < m["plain_measure"]
    # the refinement costs iterations (the plain oracle's iterate is not at tol) and two pairs each, plus
    # the refined iterate's residual (one pair) and the set-up's; the looks are left out
    extra = m["iterations"] - plain["iterations"]
    assert extra >= 5
    assert 2 * extra <= m["pairs"] - plain["pairs"] <= 2 * extra + 4
    assert m["look_pairs"] >= 1
    # it stops at the first iterate that meets the test: the iteration before it was looked at and failed
    (its_before, _, before), (its_last, _, last) = m["looks"][-2:]
    assert its_before == its_last - 1 and before > tol >= last == m["measure"]
