"""The fallback after full Newton steps fail (snes.ncp_solve, SolverSettings.fallback): the order of the
attempts with a stand-in for one attempt, and whole solves it rescues."""
import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import random_surface

from vecontact.core.pfft import SlabFFT
from vecontact.solver.settings import SolverSettings


def _stand_in(calls, converged_at):
    """A stand-in for one attempt (_ncp_solve) that records its start, options, stall count and edge
    window, and converges at attempt ``converged_at``."""
    def attempt(op, g0, tol, max_it, settings, options, monitor):
        calls.append((g0, dict(options or {}), settings.fallback_stall, settings.edge_window, max_it))
        converged = len(calls) == converged_at
        info = dict(iterations=10 * len(calls), linear_iterations=100 * len(calls), residual=1e-9 if converged
                    else 1.0, seconds=1.0, converged=converged, edge_stalled=False)
        return np.full(2, float(len(calls))), None, None, info
    return attempt


def test_a_solve_that_full_steps_cannot_converge_starts_again_with_the_vi_method(monkeypatch):
    """ncp_solve's attempts, with a stand-in for one attempt: full steps that end unconverged are
    followed, with fallback vi (the default), by PETSc's reduced-space VI Newton with the bt line
    search (a failed search still taking its step) from the same first iterate, to fallback_max_it
    and without the stall rule; the info counts both and keeps the full steps' attempt under
    "fallback_retry". No fallback when the user chose a line search or the VI method, nor with
    fallback none."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 2))
    g0 = np.zeros(2)
    s = SolverSettings()
    assert s.fallback == "vi"
    g, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {"ksp_type": "fgmres"})
    assert [c[1].get("snes_type") for c in calls] == [None, "vinewtonrsls"]
    assert calls[1][1]["snes_linesearch_type"] == "bt" and calls[1][1]["snes_max_fail"] == "300"
    assert [c[4] for c in calls] == [100, s.fallback_max_it] and s.fallback_max_it == 300
    assert calls[0][0] is g0 and calls[1][0] is g0 and all(c[1]["ksp_type"] == "fgmres" for c in calls)
    assert [c[2] for c in calls] == [s.fallback_stall, 0]
    assert info["converged"] and info["iterations"] == 30 and info["linear_iterations"] == 300
    assert info["seconds"] == 2.0 and info["fallback_retry"]["iterations"] == 10
    for settings, options in ((s, {"snes_linesearch_type": "bt"}), (s, {"snes_type": "vinewtonrsls"}),
                              (SolverSettings(fallback="none"), {})):
        calls.clear()
        snes.ncp_solve(None, g0, 1e-8, 100, settings, options)
        assert len(calls) == 1 and calls[0][2] == 0     # no fallback: no stall rule either


def test_a_line_search_fallback_runs_before_full_steps_from_its_last_iterate(monkeypatch):
    """fallback bt: the line search's attempt from the first iterate to fallback_max_it, then, if that
    one stops short, full steps from its last iterate to max_it, both without the stall rule."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 3))
    g0 = np.zeros(2)
    s = SolverSettings(fallback="bt")
    g, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {"ksp_type": "fgmres"})
    assert [c[1].get("snes_linesearch_type") for c in calls] == [None, "bt", None]
    assert calls[0][0] is g0 and calls[1][0] is g0 and np.array_equal(calls[2][0], np.full(2, 2.0))
    assert calls[1][1]["snes_max_fail"] == "300" and "snes_max_fail" not in calls[2][1]
    assert [c[4] for c in calls] == [100, 300, 100]
    assert [c[2] for c in calls] == [s.fallback_stall, 0, 0]
    assert [c[3] for c in calls] == [s.edge_window] * 3
    assert info["converged"] and info["iterations"] == 60 and info["linear_iterations"] == 600
    assert info["seconds"] == 3.0 and info["fallback_retry"]["iterations"] == 10


def test_the_line_search_goes_without_the_edge_term_when_it_stalled_the_full_steps(monkeypatch):
    """Full steps that were retried without the edge term (info["edge_retry"]) hand a line search's
    attempt, and the full steps after it, settings without the term; the retry stays in the
    diagnostics after either fallback."""
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
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 100, SolverSettings(edge_window=2, fallback="bt"), {})
    assert windows == [2, 0, 0] and not info["converged"] and info["iterations"] == 15
    assert info["edge_retry"]["iterations"] == 8
    windows.clear()
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 100, SolverSettings(edge_window=2, fallback="vi"), {})
    assert len(windows) == 2 and info["edge_retry"]["iterations"] == 8 and info["iterations"] == 10


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


@pytest.mark.parametrize("fallback", ["vi", "bt"])
def test_the_sls_rubber_at_one_mm_per_second_converges_with_the_fallback(fallback):
    """The SLS rubber (E0 3 MPa, Einf 300 MPa, tau 10 us; loss angle up to 79 deg) at 1 mm/s on the
    tests' 64^2 surface, 18 % in contact: full steps wander (measure 14 after 108 Newton iterations
    without the stall rule, measured with this machine's FFTW plans); they stop once fallback_stall
    iterations pass without a new lowest measure (33 in all here), and the fallback's attempt (the VI
    method with bt: 9 more, measured; bt on the full steps: 19) converges to a contact solution (checked
    on its fields: reference.cases), the same one with either."""
    from reference.cases import assert_contact_solution, solve_full
    from vecontact.physics.modulus import SLS
    n = 64
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * 0.001]))[0]))
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    r, fields = solve_full(h, L_PAPER, mod, 0.001, sigma0, fft=fft, petsc_options=["-vc_fallback", fallback])
    assert r.converged and 0.1 < r.area < 0.3
    first = r.diagnostics["fallback_retry"]
    assert first is not None and first["residual"] > 1.0 and r.iterations > first["iterations"]
    assert first["iterations"] < SolverSettings().newton_max_it     # the stall, not the iteration cap
    assert_contact_solution(r, fields, h, sigma0)
