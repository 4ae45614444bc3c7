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

    def oracle(memory):
        return oracle_solve(ContactOperator(fft, L_PAPER, hn, v, sigma0, h), act, 1e-8, 500, SolverSettings(),
                            memory=memory)

    full = oracle(6e9)
    assert full["restart"] == 500 and full["converged"] and full["iterations"] < 500
    # every iteration applies c_CC and m_CC: two FFT pairs, plus the set-up's
    assert 2 * full["iterations"] <= full["pairs"] <= 2 * full["iterations"] + 4
    # a basis of 11 vectors' memory (two float64 vectors an iteration): restarted every 10, more iterations
    # (GMRES minimises the residual over its whole Krylov space, a restarted one over less)
    short = oracle(16.0 * n_set * 11)
    assert short["restart"] == 10 and short["converged"]
    assert full["iterations"] > 10 and short["iterations"] > full["iterations"]
