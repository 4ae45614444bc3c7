"""The line search after full Newton steps fail (snes.ncp_solve, SolverSettings.fallback_linesearch):
the order of the attempts with a stand-in for one attempt, and a whole solve it rescues."""
import numpy as np
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import random_surface

from vecontact.core.pfft import SlabFFT
from vecontact.solver.settings import SolverSettings


def test_a_solve_that_full_steps_cannot_converge_starts_again_with_a_line_search(monkeypatch):
    """ncp_solve's attempts, with a stand-in for one attempt (_ncp_solve): full steps that end
    unconverged are followed by an attempt from the same first iterate with fallback_linesearch, then,
    if that one stops short, by full steps from its last iterate; the info counts all of them and
    keeps the full steps' first attempt under "linesearch_retry". No line search when the user chose
    one, nor with fallback_linesearch none."""
    import vecontact.solver.snes as snes
    calls = []

    def attempt(op, g0, tol, max_it, settings, options, monitor):
        calls.append((g0, dict(options or {}), settings.fallback_stall, settings.edge_window))
        ls = (options or {}).get("snes_linesearch_type")
        converged = len(calls) == 3
        info = dict(iterations=10 * len(calls), linear_iterations=100 * len(calls), residual=1e-9 if converged
                    else 1.0, seconds=1.0, converged=converged, edge_stalled=False, ls=ls)
        return np.full(2, float(len(calls))), None, None, info

    monkeypatch.setattr(snes, "_ncp_solve", attempt)
    g0 = np.zeros(2)
    g, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, SolverSettings(), {"ksp_type": "fgmres"})
    assert [c[1].get("snes_linesearch_type") for c in calls] == [None, SolverSettings().fallback_linesearch, None]
    assert calls[0][0] is g0 and calls[1][0] is g0 and np.array_equal(calls[2][0], np.full(2, 2.0))
    assert all(c[1]["ksp_type"] == "fgmres" for c in calls)
    assert calls[1][1]["snes_max_fail"] == "100" and "snes_max_fail" not in calls[2][1]
    # only the full steps before the line search stop at a stall; the attempts after it run to max_it
    assert [c[2] for c in calls] == [SolverSettings().fallback_stall, 0, 0]
    assert [c[3] for c in calls] == [SolverSettings().edge_window] * 3
    assert info["converged"] and info["iterations"] == 60 and info["linear_iterations"] == 600
    assert info["seconds"] == 3.0 and info["linesearch_retry"]["iterations"] == 10
    for settings, options in ((SolverSettings(), {"snes_linesearch_type": "bt"}),
                              (SolverSettings(fallback_linesearch="none"), {})):
        calls.clear()
        snes.ncp_solve(None, g0, 1e-8, 100, settings, options)
        assert len(calls) == 1 and calls[0][2] == 0     # no fallback: no stall rule either


def test_the_line_search_goes_without_the_edge_term_when_it_stalled_the_full_steps(monkeypatch):
    """Full steps that were retried without the edge term (info["edge_retry"]) hand the line search's
    attempt, and the full steps after it, settings without the term."""
    import vecontact.solver.snes as snes
    windows = []

    def attempt(op, g0, tol, max_it, settings, options, monitor):
        windows.append(settings.edge_window)
        info = dict(iterations=5, linear_iterations=50, residual=1.0, seconds=1.0, converged=False,
                    edge_stalled=False)
        if len(windows) == 1:
            info["edge_retry"] = dict(iterations=8, linear_iterations=80, residual=2.0, seconds=1.0)
        return np.zeros(2), None, None, info

    monkeypatch.setattr(snes, "_ncp_solve", attempt)
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 100, SolverSettings(edge_window=2), {})
    assert windows == [2, 0, 0] and not info["converged"] and info["iterations"] == 15
    assert info["edge_retry"]["iterations"] == 8        # the full steps' retry stays in the diagnostics


def test_the_stall_count_runs_from_the_lowest_measure_after_the_start():
    """_Convergence._measure_stalled: true once fallback_stall Newton iterations have passed since the
    lowest measure after the start (ties are no new lowest; the start's own measure does not count);
    never with fallback_stall 0."""
    from vecontact.solver.snes import _Convergence
    conv = _Convergence(None, None, 1e-8, None, settings=SolverSettings(fallback_stall=3))
    seq = [(0, 1.0), (1, 7.0), (2, 4.0), (3, 4.0), (4, 6.0), (5, 9.0), (6, 3.0), (7, 5.0), (8, 5.0), (9, 5.0)]
    assert [conv._measure_stalled(it, r) for it, r in seq] == [False] * 5 + [True, False, False, False, True]
    off = _Convergence(None, None, 1e-8, None, settings=SolverSettings(fallback_stall=0))
    assert not any(off._measure_stalled(it, 1.0) for it in range(50))


def test_the_sls_rubber_at_one_mm_per_second_converges_with_the_line_search():
    """The SLS rubber (E0 3 MPa, Einf 300 MPa, tau 10 us; loss angle up to 79 deg) at 1 mm/s on the
    tests' 64^2 surface, 18 % in contact: full steps wander (measure 14 after 108 Newton iterations
    without the stall rule, measured with this machine's FFTW plans); they stop once fallback_stall
    iterations pass without a new lowest measure (33 in all here), and the line search's attempt,
    finished by full steps, converges to a contact solution (checked on its fields: reference.cases)."""
    from reference.cases import assert_contact_solution, solve_full
    from vecontact.physics.modulus import SLS
    n = 64
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * 0.001]))[0]))
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    r, fields = solve_full(h, L_PAPER, mod, 0.001, sigma0, fft=fft)
    assert r.converged and 0.1 < r.area < 0.3
    first = r.diagnostics["linesearch_retry"]
    assert first is not None and first["residual"] > 1.0 and r.iterations > first["iterations"]
    assert first["iterations"] < SolverSettings().newton_max_it     # the stall, not the iteration cap
    assert_contact_solution(r, fields, h, sigma0)
