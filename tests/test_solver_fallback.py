"""The fallback after full Newton steps fail (snes.ncp_solve, SolverSettings.fallback): the order of the
attempts with a stand-in for one attempt, and whole solves it rescues."""
from dataclasses import replace

import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import random_surface

from vecontact.core.pfft import SlabFFT
from vecontact.solver.settings import SolverSettings


def _stand_in(calls, converged_at):
    """A stand-in for one attempt (_ncp_solve) that records its start, options, stall count, edge
    window, Newton iterations and coarse stall floor, and converges at attempt ``converged_at``."""
    def attempt(op, g0, tol, max_it, settings, options, monitor, stall_above=0.0):
        calls.append((g0, dict(options or {}), settings.fallback_stall, settings.edge_window, max_it, stall_above))
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

    def attempt(op, g0, tol, max_it, settings, options, monitor, stall_above=0.0):
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
    # the VI attempt (no edge term of its own) fails too: bt without the term follows, then full steps
    assert windows == [2, 2, 0, 0] and info["edge_retry"]["iterations"] == 8 and info["iterations"] == 20
    assert info["vi_retry"]["iterations"] == 5 and not info["converged"]


def test_a_direct_solve_starts_with_the_fallback_s_attempt(monkeypatch):
    """ncp_solve(direct=True), as contact.py calls it on the grids finer than one that needed the
    fallback: no full steps; the fallback's attempt (vi, or bt then full steps if it stops short) runs
    from g0 to fallback_max_it without the stall rule, and info says so (fallback_direct, no
    fallback_retry).  With no fallback (fallback none, a user's line search or VI method) direct is
    ignored: the full steps as usual."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 1))
    g0 = np.zeros(2)
    s = SolverSettings()
    _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {}, direct=True)
    assert [c[1].get("snes_type") for c in calls] == ["vinewtonrsls"] and calls[0][0] is g0
    assert calls[0][1]["snes_linesearch_type"] == "bt" and [c[4] for c in calls] == [s.fallback_max_it]
    assert calls[0][2] == 0 and info["fallback_direct"] and "fallback_retry" not in info
    assert info["converged"] and info["iterations"] == 10
    calls.clear()
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 2))
    _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, SolverSettings(fallback="bt"), {}, direct=True)
    assert [c[1].get("snes_linesearch_type") for c in calls] == ["bt", None] and [c[4] for c in calls] == [300, 100]
    assert info["converged"] and info["fallback_direct"] and info["iterations"] == 30
    for settings, options in ((SolverSettings(fallback="none"), {}), (s, {"snes_linesearch_type": "bt"}),
                              (s, {"snes_type": "vinewtonrsls"})):
        calls.clear()
        monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 1))
        _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, settings, options, direct=True)
        assert len(calls) == 1 and calls[0][1] == options and "fallback_direct" not in info


def test_a_direct_attempt_that_fails_is_followed_by_full_steps_and_bt(monkeypatch):
    """ncp_solve(direct=True) whose VI attempt does not converge: the ordinary attempts follow from the
    same g0, full steps (with the stall rule) and then bt on the full steps (not the VI method again);
    every attempt counts, info["direct_retry"] holds the VI attempt, fallback_direct stays True."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 3))
    g0 = np.zeros(2)
    s = SolverSettings()
    _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {}, direct=True)
    assert [c[1].get("snes_type") for c in calls] == ["vinewtonrsls", None, None]
    assert [c[1].get("snes_linesearch_type") for c in calls] == ["bt", None, "bt"]
    assert [c[2] for c in calls] == [0, s.fallback_stall, 0] and all(c[0] is g0 for c in calls)
    assert info["converged"] and info["fallback_direct"] and info["iterations"] == 60
    assert info["direct_retry"]["iterations"] == 10 and info["fallback_retry"]["iterations"] == 20


def test_the_attempts_after_a_failed_direct_attempt_take_no_coarse_floor(monkeypatch):
    """ncp_solve(direct=True, fallback_above=x), a coarse grid's direct VI attempt that fails: the ordinary
    attempts that follow run without x (a choice, measured: RESULTS.md, "`coarse_stall`"), so their full
    steps have no coarse stall floor and bt follows them even where they end at a measure below x."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 0))     # no attempt converges: all end at 1.0
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 50, SolverSettings(), {}, direct=True, fallback_above=2.0)
    assert [c[1].get("snes_linesearch_type") for c in calls[:3]] == ["bt", None, "bt"]
    assert [c[5] for c in calls] == [0.0] * len(calls) and not info["converged"]
    assert info["fallback_direct"] and info["direct_retry"]["iterations"] == 10
    assert info["fallback_retry"]["iterations"] == 20


def test_a_vi_attempt_that_fails_after_full_steps_is_followed_by_bt(monkeypatch):
    """ncp_solve after failed full steps whose VI attempt fails too (vi_stall, say): bt on the full steps
    from the same g0 follows, to fallback_max_it and without the stall rule; every attempt counts,
    info["vi_retry"] holds the VI attempt and info["fallback_retry"] the full steps'.  A VI attempt
    that converges is not followed by one."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 3))
    g0 = np.zeros(2)
    s = SolverSettings()
    _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {})
    assert [c[1].get("snes_type") for c in calls] == [None, "vinewtonrsls", None]
    assert [c[1].get("snes_linesearch_type") for c in calls] == [None, "bt", "bt"]
    assert [c[2] for c in calls] == [s.fallback_stall, 0, 0] and all(c[0] is g0 for c in calls)
    assert [c[4] for c in calls] == [100, s.fallback_max_it, s.fallback_max_it]
    assert info["converged"] and info["iterations"] == 60
    assert info["vi_retry"]["iterations"] == 20 and info["fallback_retry"]["iterations"] == 10
    calls.clear()
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 2))
    _, _, _, info = snes.ncp_solve(None, g0, 1e-8, 100, s, {})
    assert len(calls) == 2 and info["converged"] and "vi_retry" not in info


def test_a_vi_attempt_ends_once_its_measure_stops_reaching_a_new_lowest():
    """_Convergence._measure_stalled for the VI method's form (the fallback's attempt, fallback_stall 0, or
    the user's): true once vi_stall Newton iterations have passed since its lowest measure; returns are
    not looked for (no cycle rule); never with vi_stall 0."""
    from vecontact.solver.snes import _Convergence
    from vecontact.solver.vi import ViNewton
    S = replace(SolverSettings(), fallback_stall=0)
    assert S.vi_stall == 20 and SolverSettings().cycle_rtol > 0
    vi = ViNewton.__new__(ViNewton)
    seq = [(0, 50.0), (1, 30.0), (2, 19.7)] + [(it, 19.8 + 0.1 * (it % 2)) for it in range(3, 30)]
    on = _Convergence(None, None, 1e-8, None, form=vi, settings=S)
    assert [on._measure_stalled(it, r) for it, r in seq].index(True) == 2 + S.vi_stall
    off = _Convergence(None, None, 1e-8, None, form=vi, settings=replace(S, vi_stall=0))
    assert not any(off._measure_stalled(it, r) for it, r in seq)
    full = _Convergence(None, None, 1e-8, None, settings=S)       # full steps without the stall rule
    assert not any(full._measure_stalled(it, r) for it, r in seq)


def test_full_steps_that_end_near_their_tolerance_take_no_fallback_when_asked(monkeypatch):
    """ncp_solve(fallback_above=x), as contact.py calls it on the coarse grids (fallback_coarse_measure):
    full steps that end unconverged at a measure of at most x end the solve; above x the fallback
    follows."""
    import vecontact.solver.snes as snes
    calls = []
    monkeypatch.setattr(snes, "_ncp_solve", _stand_in(calls, 2))    # the full steps end at 1.0
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 50, SolverSettings(), {}, fallback_above=1.0)
    assert len(calls) == 1 and not info["converged"] and "fallback_retry" not in info
    calls.clear()
    _, _, _, info = snes.ncp_solve(None, np.zeros(2), 1e-8, 50, SolverSettings(), {}, fallback_above=0.99)
    assert len(calls) == 2 and info["converged"] and info["fallback_retry"]["residual"] == 1.0
    # x is the full steps' coarse stall floor (_Convergence._coarse_stalled), not the fallback's; none
    # without a fallback to hand over to
    assert [c[5] for c in calls] == [0.99, 0.0]
    calls.clear()
    snes.ncp_solve(None, np.zeros(2), 1e-8, 50, SolverSettings(fallback="none"), {}, fallback_above=0.99)
    assert [c[5] for c in calls] == [0.0]


def test_a_coarse_grid_s_full_steps_end_once_they_wander_above_the_fallback_s_threshold():
    """_Convergence._coarse_stalled (a coarse grid's full steps: stall_above, ncp_solve's fallback_above):
    true once coarse_stall Newton iterations have passed since the lowest measure while that lowest is
    above stall_above; never once the lowest is at or below it, never for the VI method's attempts,
    never with coarse_stall 0 or on the finest grid (stall_above 0)."""
    from vecontact.solver.snes import _Convergence
    from vecontact.solver.vi import ViNewton
    S = replace(SolverSettings(), fallback_stall=0, coarse_stall=10)   # the coarse grids' settings (contact.py)

    def fired(seq, stall_above=10.0, settings=S, form=None):
        conv = _Convergence(None, None, 1e-8, None, form=form, settings=settings, stall_above=stall_above)
        out = []
        for it, r in enumerate(seq):
            assert not conv._measure_stalled(it, r)             # fallback_stall 0: only the coarse rule
            out.append(conv._coarse_stalled(it))
        return out.index(True) if True in out else None
    # a 128^2 grid's wandering (SLS rubber, session 83): lowest 104 at iteration 3
    wander = [900.0, 420.0, 230.0, 104.0, 2300.0, 380.0, 5100.0, 160.0, 620.0, 104.5, 1900.0, 250.0, 700.0,
              130.0, 3300.0, 180.0]
    assert fired(wander) == 3 + 10
    assert fired(wander, stall_above=200.0) is None         # its lowest is below the floor
    assert fired(wander, stall_above=0.0) is None
    assert fired(wander, settings=replace(S, coarse_stall=0)) is None
    assert fired(wander, form=ViNewton.__new__(ViNewton)) is None
    assert fired(wander[:4] + [99.0] + wander[5:]) == 4 + 10      # a new lowest restarts the count


@pytest.mark.parametrize("switch", ["on", "off"])
def test_after_a_coarse_grid_that_needed_the_fallback_the_finer_grids_start_with_it(monkeypatch, switch):
    """solve_contact's grid chain, with a stand-in for ncp_solve that fails the full steps of the
    second of three grids (64^2, 128^2, 256^2): with fallback_coarse on, that grid takes the
    fallback (to coarse_max_it, without the stall rule, if its measure ended above
    fallback_coarse_measure) and every finer grid is solved with
    direct=True; the first grid, solved before, is not.  With it off, no coarse grid takes the fallback
    and none is direct."""
    import vecontact.solver.contact as contact
    import vecontact.solver.snes as snes
    from vecontact.solver import solve_contact
    seen = []

    def stand_in(op, g0, tol, max_it, settings, options=None, monitor=None, direct=False, fallback_above=0.0):
        n = op.fft.N
        fb = settings.fallback != "none" and not direct and n == 128
        seen.append((n, direct, settings.fallback, settings.fallback_stall, settings.fallback_max_it, max_it,
                     fallback_above, settings.coarse_stall))
        info = dict(iterations=3, linear_iterations=9, residual=1e-12, seconds=0.0, converged=True,
                    reason=2, history=[], nchg=[], lin_history=[], modes=[], measures=(0.0, 0.0, 0.0))
        if fb:
            info["fallback_retry"] = dict(iterations=50, linear_iterations=500, residual=1.0, seconds=0.0)
        if direct:
            info["fallback_direct"] = True
        g = np.ones(op.fft.local_real_shape)
        return g, np.zeros_like(g), np.zeros(g.shape, bool), info

    monkeypatch.setattr(snes, "ncp_solve", stand_in)
    n = 256
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    from vecontact.physics.modulus import SLS
    r = solve_contact(fft, L_PAPER, h, SLS(3e6, 3e8, 1e-5, NU), 0.001, 1e4, store=(),
                      petsc_options=["-vc_fallback_coarse", switch])
    s = SolverSettings()
    coarse_fb = s.fallback if switch == "on" else "none"
    assert [x[0] for x in seen] == [64, 128, 256]
    assert [x[1] for x in seen] == ([False, False, True] if switch == "on" else [False, False, False])
    coarse = (coarse_fb, 0, s.coarse_max_it, s.coarse_max_it, s.fallback_coarse_measure)
    # the coarse stall rule from coarse_stall_min_n (128) up, so not on 64^2; the finest grid's is off
    # (fallback_above 0)
    assert s.coarse_stall > 0 and s.coarse_stall_min_n == 128
    assert seen[0][2:] == coarse + (0,) and seen[1][2:] == coarse + (s.coarse_stall,)
    assert seen[2][2:-1] == (s.fallback, s.fallback_stall, s.fallback_max_it, s.newton_max_it, 0.0)
    levels = r.diagnostics["levels"]
    assert [lv["fallback_direct"] for lv in levels] == [False, False, switch == "on"]
    assert r.diagnostics["fallback_direct"] == (switch == "on")
    assert (levels[1]["fallback_retry"] is not None) == (switch == "on")


def test_the_stall_count_runs_from_the_lowest_measure_after_the_start():
    """_Convergence._measure_stalled: true once fallback_stall Newton iterations have passed since the
    lowest measure after the start (ties are no new lowest; the start's own measure does not count),
    edge_stall once a step has used the edge term; never with fallback_stall 0.  (The cycle rule off:
    the ties here would be cycles, next test.)"""
    from types import SimpleNamespace
    from vecontact.solver.snes import _Convergence
    conv = _Convergence(None, None, 1e-8, None, settings=SolverSettings(fallback_stall=3, edge_stall=5, cycle_rtol=0))
    seq = [(0, 1.0), (1, 7.0), (2, 4.0), (3, 4.0), (4, 6.0), (5, 9.0), (6, 3.0), (7, 5.0), (8, 5.0), (9, 5.0)]
    assert [conv._measure_stalled(it, r) for it, r in seq] == [False] * 5 + [True, False, False, False, True]
    edge = _Convergence(None, None, 1e-8, None, form=SimpleNamespace(edge_used=True),
                        settings=SolverSettings(fallback_stall=3, edge_stall=5, cycle_rtol=0))
    seq = [(0, 1.0), (1, 7.0), (2, 4.0)] + [(it, 6.0) for it in range(3, 9)]
    assert [edge._measure_stalled(it, r) for it, r in seq] == [False] * 7 + [True, True]
    for form in (None, SimpleNamespace(edge_used=True)):
        off = _Convergence(None, None, 1e-8, None, form=form, settings=SolverSettings(fallback_stall=0))
        assert not any(off._measure_stalled(it, 1.0) for it in range(50))


def test_full_steps_that_cycle_stop_at_the_first_return():
    """_Convergence._measure_stalled: true as soon as the measure comes back to within cycle_rtol of one
    2 to cycle_period iterates before, the last one differing, long before the stall count (where
    fallback_stall counts).  The
    sequence is the SLS rubber's at 1024^2, 0.1 mm/s (RESULTS.md, "`cycle_rtol`"): a 3-cycle whose
    measures repeat to 1e-6 and now and then reach a new lowest by 1e-9, so the count alone waited 25
    iterations."""
    from vecontact.solver.snes import _Convergence
    cyc = [128.3446115802464, 220.80595819742814, 170.93266187928808, 128.34505900724557, 220.805675021789,
           170.9326464595539, 128.34452491418259, 220.8061717601258]
    seq = list(enumerate([5930.9, 4876.0, 1908.3, 2688.9, 244.5, 192.2] + cyc))
    S = SolverSettings()
    assert S.cycle_rtol > 0 and S.cycle_period >= 3 and S.fallback_stall > 0
    on = _Convergence(None, None, 1e-8, None, settings=S)
    assert [on._measure_stalled(it, r) for it, r in seq].index(True) == 9      # 128.345 after 128.3446
    for off in (replace(S, cycle_rtol=0), replace(S, fallback_stall=0), replace(S, cycle_period=2)):
        conv = _Convergence(None, None, 1e-8, None, settings=off)
        assert not any(conv._measure_stalled(it, r) for it, r in seq)
    # within 1e-4, not 1e-5, is no return; nor is a plateau that creeps (the 64^2 sharp rubber's, which
    # got out at its 19th iteration and converged at its 27th); a 2-cycle is one
    conv = _Convergence(None, None, 1e-8, None, settings=S)
    assert not any(conv._measure_stalled(it, r) for it, r in enumerate([10.0, 5.0, 8.0, 5.0005, 4.0]))
    creep = [30.29, 32.40, 20.89, 16.16, 15.39, 14.12, 13.499, 13.6216, 13.2308, 13.1767, 13.1731, 13.1713,
             13.1714, 13.1709, 13.1701, 13.168, 13.1667, 13.1667, 9.77]
    conv = _Convergence(None, None, 1e-8, None, settings=S)
    assert not any(conv._measure_stalled(it, r) for it, r in enumerate(creep, 1))
    conv = _Convergence(None, None, 1e-8, None, settings=S)
    assert [conv._measure_stalled(it, r) for it, r in enumerate([9.0, 7.0, 3.0, 7.0 * (1 + 2e-6)])] == [False] * 3 + [True]


@pytest.mark.parametrize("fallback", ["vi", "bt"])
def test_the_sls_rubber_at_one_mm_per_second_converges_with_the_fallback(fallback):
    """The SLS rubber (E0 3 MPa, Einf 300 MPa, tau 10 us; loss angle up to 79 deg) at 1 mm/s on the
    tests' 64^2 surface (seed 7), 18 % in contact: full steps wander (their lowest measure 13.4 in 108
    Newton iterations without the stall rule); they stop once fallback_stall iterations pass without a
    new lowest measure (22 in all, the lowest 13.7 at 9; 32 with a count of 20), and the fallback's
    attempt (the VI method with bt: 11 more; bt on the full steps: 21) converges to a contact
    solution (checked on its fields: reference.cases), the same one with either.  All measured, and
    the same with each of numpy's OpenBLAS kernels (OPENBLAS_CORETYPE Haswell, SkylakeX, Sandybridge,
    Prescott): the path rounds with them, and seed 4's full steps converged with two of the four."""
    from reference.cases import assert_contact_solution, solve_full
    from vecontact.physics.modulus import SLS
    n = 64
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=7)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * 0.001]))[0]))
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    r, fields = solve_full(h, L_PAPER, mod, 0.001, sigma0, fft=fft, petsc_options=["-vc_fallback", fallback])
    assert r.converged and 0.1 < r.area < 0.3
    first = r.diagnostics["fallback_retry"]
    assert first is not None and first["residual"] > 1.0 and r.iterations > first["iterations"]
    assert first["iterations"] < SolverSettings().newton_max_it     # the stall, not the iteration cap
    assert_contact_solution(r, fields, h, sigma0)


def test_a_coarse_grid_that_needs_the_fallback_hands_it_to_the_finer_grid():
    """The SLS rubber at 1 mm/s on the paper's 256^2 surface, sigma0 = 1e-4 |E(8 q0 v)| (0.24 % in
    contact): the full steps cannot solve the 128^2 coarse grid (50 Newton iterations, measured), nor
    the 256^2 one (the stall rule hands it to the fallback after 46).  With fallback_coarse on, the
    128^2 grid takes the fallback and the 256^2 grid starts with it: the same contact set and mu as
    with it off, in far fewer FFT pairs (measured on one rank: 1394 against 13 788, 6 Newton
    iterations on 256^2 against 54).  The coarse stall rule hands the 128^2 grid over after 7 full
    steps instead of 50 (measured; its measure stays in the thousands): 613 pairs against 1394
    without it, the same contact set and mu."""
    from reference.cases import Q0, paper_case
    from vecontact.physics.modulus import SLS
    from vecontact.solver import solve_contact
    fft, h, _ = paper_case(256)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-4 * abs(complex(mod(np.array([8 * Q0 * 0.001]))[0]))
    on, off, nostall = (solve_contact(fft, L_PAPER, h, mod, 0.001, sigma0, store=(), petsc_options=opts)
                        for opts in (["-vc_fallback_coarse", "on"], ["-vc_fallback_coarse", "off"],
                                     ["-vc_coarse_stall", "0"]))
    assert on.converged and off.converged and nostall.converged
    S = SolverSettings()
    full = [r.diagnostics["levels"][1]["fallback_retry"] for r in (on, nostall)]
    assert S.coarse_stall <= full[0]["iterations"] < S.coarse_max_it == full[1]["iterations"]
    assert full[0]["residual"] > S.fallback_coarse_measure
    assert nostall.diagnostics["levels"][2]["fallback_direct"]
    assert abs(on.area - nostall.area) * 256 ** 2 <= 1 and abs(on.mu - nostall.mu) <= 1e-8 * abs(on.mu)
    assert on.fft_pairs < 0.6 * nostall.fft_pairs, (on.fft_pairs, nostall.fft_pairs)
    lv_on, lv_off = on.diagnostics["levels"], off.diagnostics["levels"]
    assert [lv["N"] for lv in lv_on] == [64, 128, 256]
    assert lv_on[1]["fallback_retry"] is not None and lv_on[2]["fallback_direct"]
    assert lv_on[2]["fallback_retry"] is None and on.diagnostics["fallback_direct"]
    assert lv_off[1]["fallback_retry"] is None and not lv_off[1]["converged"]
    assert lv_off[2]["fallback_retry"] is not None and not lv_off[2]["fallback_direct"]
    assert abs(on.area - off.area) * 256 ** 2 <= 1
    assert abs(on.mu - off.mu) <= 1e-8 * abs(off.mu)
    assert on.fft_pairs < off.fft_pairs / 3, (on.fft_pairs, off.fft_pairs)
    # each level's measure history (its last attempt's): the failed coarse grid's 50 full steps from
    # its start, every level ending at its residual, the finest's the result's own history
    assert len(lv_off[1]["history"]) == SolverSettings().coarse_max_it + 1
    for r in (on, off, nostall):
        for lv in r.diagnostics["levels"]:
            assert lv["history"] and abs(lv["history"][-1] - lv["residual"]) <= 1e-12 * lv["residual"]
        assert r.diagnostics["levels"][-1]["history"] == [m for _, m in r.diagnostics["history"]]


def test_a_solve_whose_full_steps_cycle_hands_over_at_the_return():
    """The sharp rubber (alpha = beta = 0.8, tau 1 us) at 1 cm/s on the tests' 64^2 surface (seed 18),
    sigma0 = 3e-3 |E(8 q0 v)|, 61 % in contact: the full steps settle into a 2-cycle (9.4895, 9.4911,
    9.4895 at iterations 15-17) and hand over at its first return, before the stall count (their
    lowest, 9.4877, was at iteration 13); with cycle_rtol 0 they run on until the count fires (at 23).
    Both converge to the same contact set and mu.  All measured, and the same with each of numpy's
    OpenBLAS kernels (OPENBLAS_CORETYPE Haswell, SkylakeX, Sandybridge, Prescott): the path rounds
    with them, and seed 7's full steps cycled with SkylakeX's and stalled with Haswell's."""
    from vecontact.physics.modulus import HavriliakNegami
    from vecontact.solver import solve_contact
    n, v = 64, 0.01
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=18)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    sigma0 = 3e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * v]))[0]))
    # the path rounds with the FFT plans (the estimate planner's from empty wisdom: conftest.py) and the
    # BLAS kernels (the docstring)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    S = SolverSettings()
    runs = {}
    for rtol in (S.cycle_rtol, 0.0):
        seen = []
        r = solve_contact(fft, L_PAPER, h, mod, v, sigma0, store=("pressure",),
                          petsc_options=["-vc_cycle_rtol", str(rtol)], monitor=lambda N, it, m: seen.append((it, m)))
        first = r.diagnostics["fallback_retry"]
        assert r.converged and first is not None
        steps = [m for it, m in seen[:first["iterations"] + 1]]       # the full steps' attempt, from its start
        assert [it for it, _ in seen[:first["iterations"] + 1]] == list(range(first["iterations"] + 1))
        low = 1 + int(np.argmin(steps[1:]))
        runs[rtol] = r, steps, low
    (on, steps, low), (off, steps_off, low_off) = runs[S.cycle_rtol], runs[0.0]
    k = len(steps) - 1
    assert k < low + S.fallback_stall                                  # not the count
    assert any(abs(steps[k] - steps[k - j]) <= S.cycle_rtol * steps[k] for j in range(2, S.cycle_period + 1))
    assert abs(steps[k] - steps[k - 1]) > S.cycle_rtol * steps[k]
    assert len(steps_off) - 1 == low_off + S.fallback_stall and len(steps_off) > len(steps)
    assert np.array_equal(on.pressure > 0, off.pressure > 0)
    assert abs(on.mu - off.mu) <= 1e-8 * abs(off.mu)
