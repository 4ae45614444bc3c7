"""The step policy of the Newton solve (vecontact/solver/policy.py): pure rules, tested without PETSc.

Tolerances are products of the decimal settings, so they are compared to rounding (rel 1e-15)."""
import pytest

from vecontact.solver.policy import StepPolicy, choose_step, tighten_steps
from vecontact.solver.settings import SolverSettings

S = SolverSettings()
ROUND = dict(rel=1e-15)


@pytest.mark.parametrize("changes, residuals, tighter", [
    ([-1, 69409, 29531], [1e-1, 1e-2, 1e-3], True),     # 4096^2, 1 m/s, 28 %: shrinks only 2.4x: wanders
    ([-1, 3035, 340], [1e-1, 1e-2, 1e-3], False),      # shrinks 9x: keep the loose steps
    ([-1, 3035, 340, 3], [1, 0.1, 0.01, 1e-3], False),
    ([-1, 100, 120], [1e-1, 1e-2, 1e-3], True),        # grew
    ([-1, 100, 10], [1e-1, 1e-2, 2e-2], True),         # the residual did not fall
    ([-1, 100], [1e-1, 1e-2], False),                  # one step says nothing
    ([-1, 100, 0], [1e-1, 1e-2, 1e-3], False),
    ([-1, 0, 0], [1e-1, 1e-2, 1e-3], False),
])
def test_tighten_steps(changes, residuals, tighter):
    """Tighter steps when the set changes grow or shrink by less than 1 / wander_ratio (= 3.3x) per
    step, or when the residual does not fall."""
    assert S.wander_ratio == 0.3
    assert tighten_steps(changes, residuals, S.wander_ratio) is tighter


def test_choose_step():
    n = 64.0 ** 2
    area = S.step_area(1.0, 64)
    assert choose_step("auto", int(area * n), n, area) == "contact"
    assert choose_step("auto", int(area * n) + 1, n, area) == "free"
    assert choose_step("contact", n, n, area) == "contact" and choose_step("free", 1, n, area) == "free"


def _run(policy, steps):
    """Feed (residual of the iterate, active-set change, mode) per Newton step; the tolerances."""
    out = []
    for res, change, mode in steps:
        policy.record_residual(res)
        out.append(policy.step(change, mode))
    return out


def test_loose_while_the_set_changes_then_exact():
    atol = 1e-8 / 2.0
    p = StepPolicy(S, atol)
    got = _run(p, [(1.0, -1, "contact"), (0.1, 3035, "contact"), (0.01, 340, "free"), (1e-3, 0, "free"),
                   (1e-4, 0, "contact")])
    first, changing, grid, exact, retry = got
    # first step of a level: 10x tighter, contact-set atol x inner_atol_factor
    assert first[0] == pytest.approx(S.first_rtol_factor * S.lin_rtol, **ROUND)
    assert first[1] == pytest.approx(atol * S.inner_atol_factor, **ROUND) and first[2] == S.lin_maxit_changing
    assert changing == (S.lin_rtol, pytest.approx(atol * S.inner_atol_factor, **ROUND), S.lin_maxit_changing)
    assert grid == (S.lin_rtol, atol, S.lin_maxit_changing)        # shrank 9x: no tightening
    assert exact == (S.exact_rtol, atol, S.ksp_max_it)              # the set stopped changing
    # the exact step did not converge: atol x atol_retry_factor
    assert retry[0] == S.exact_rtol and retry[2] == S.ksp_max_it
    assert retry[1] == pytest.approx(atol * S.atol_retry_factor * S.inner_atol_factor, **ROUND)
    assert p.changes == [-1, 3035, 340, 0, 0]


@pytest.mark.parametrize("own", [True, False])
def test_smoothing_after_changing_free_set_steps_only(own):
    """The iterate a free-set step makes while the set changes is smoothed (step_sweeps sweeps); not
    after a contact-set step nor after an exact one; whoever sets the tolerances (``own``)."""
    assert S.step_sweeps > 0
    p = StepPolicy(S, 1e-8, own=own)
    sweeps = []
    for res, change, mode in [(1.0, -1, "free"), (0.1, 30, "free"), (0.01, 3, "contact"), (1e-3, 0, "free"),
                              (1e-4, 2, "free"), (1e-5, 0, "contact")]:
        p.record_residual(res)
        p.step(change, mode)
        sweeps.append(p.sweeps)
    assert sweeps == [S.step_sweeps, S.step_sweeps, 0, 0, S.step_sweeps, 0]
    off = StepPolicy(SolverSettings(step_sweeps=0), 1e-8, own=own)
    off.step(-1, "free")
    assert off.sweeps == 0


def test_no_smoothing_once_the_iterate_came_back():
    """Once the measure comes back to the one two iterates before (within step_return_rtol), the
    smoothed steps flip the same points to and fro (the sharp rubber at 128^2, 0.001 m/s, 59 %:
    3.711866248348 and 3.711876290688 in turn, measured): no sweeps from then on. A measure that only
    comes near it (4e-3 relative, the closest return in the paper's solves) keeps them."""
    assert 1e-3 > S.step_return_rtol > 0
    p = StepPolicy(S, 1e-8)
    sweeps = []
    for res in (11.6, 6.18, 11.6 * (1 + 4e-3), 3.711866248348, 3.711876290688, 3.711866248348, 3.711876290688):
        p.record_residual(res)
        p.step(3, "free")
        sweeps.append(p.sweeps)
    assert sweeps == [S.step_sweeps] * 5 + [0, 0]
    off = StepPolicy(SolverSettings(step_return_rtol=0), 1e-8)
    for res in (1.0, 2.0, 1.0):
        off.record_residual(res)
    off.step(3, "free")
    assert off.sweeps == S.step_sweeps


def _steps_with_iterations(policy, steps):
    """Like _run, with the Krylov iterations each step took reported before the next one."""
    out = []
    for its, (res, change, mode) in steps:
        if its is not None:
            policy.record_iterations(its)
        policy.record_residual(res)
        out.append(policy.step(change, mode))
    return out


@pytest.mark.parametrize("first_mode, cap, first_its, cycles", [
    ("free", 80, 80, True),      # a changing free-set step used a whole cap of >= 80: long solves, cycles
    ("free", 80, 79, False),     # under its cap: plain GMRES stays
    ("free", 40, 40, False),     # a whole first cap of 40 at low stiffness range (where the cycles lose) is not enough
    ("contact", 80, 80, False),  # the cap of a contact-set step says nothing of the free set's
])
def test_cycles_after_a_capped_free_set_step(first_mode, cap, first_its, cycles):
    """free_cycle > 0: ``cycling`` turns on once a changing free-set step ends on an iteration cap of at
    least cycle_after_cap, and stays on; an exact free-set step then gets cycle_max_it, not ksp_max_it."""
    s = SolverSettings(free_cycle=20, ksp_max_it=400, cycle_max_it=800, cycle_after_cap=80,
                       lin_maxit_changing=cap)
    p = StepPolicy(s, 1e-8)
    got = _steps_with_iterations(p, [(None, (1.0, -1, first_mode)), (first_its, (0.1, 500, "free")),
                                     (10, (0.01, 0, "free")), (10, (1e-3, 0, "contact"))])
    assert got[0][2] == cap and p.cycling is cycles
    assert got[2][2] == (800 if cycles else 400)       # the exact free-set step
    assert got[3][2] == 400                             # contact-set steps keep ksp_max_it
    off = StepPolicy(SolverSettings(free_cycle=0), 1e-8)
    _steps_with_iterations(off, [(None, (1.0, -1, "free")), (10 ** 6, (0.1, 500, "free"))])
    assert not off.cycling                             # free_cycle 0: never


@pytest.mark.parametrize("stiffness_range, cycles", [(1.0e5, False), (2.9e5, True)])
def test_cycles_after_a_first_cap_at_high_range(stiffness_range, cycles):
    """Above cycle_range_max a whole first cap of 40 (cycle_after_cap_large) starts the cycles."""
    s = SolverSettings(free_cycle=20, lin_maxit_changing=40, cycle_after_cap=80, cycle_after_cap_large=40,
                       cycle_range_max=1.5e5)
    p = StepPolicy(s, 1e-8, stiffness_range=stiffness_range)
    _steps_with_iterations(p, [(None, (1.0, -1, "free")), (40, (0.1, 500, "free"))])
    assert p.cycle_cap == (40 if cycles else 80) and p.cycling is cycles
    under = StepPolicy(s, 1e-8, stiffness_range=stiffness_range)
    _steps_with_iterations(under, [(None, (1.0, -1, "free")), (39, (0.1, 500, "free"))])
    assert not under.cycling                           # under its cap: plain GMRES stays


def test_wandering_tightens_down_to_the_floors():
    """Each wandering step: rtol x tighten_factor down to lin_rtol_min, the iteration cap x
    tighten_maxit_factor up to ksp_max_it."""
    p = StepPolicy(S, 1.0)
    steps = [(1.0, -1, "free")] + [(0.5 ** k, 1000, "free") for k in range(1, 10)]
    got = _run(p, steps)
    rtols = [t[0] for t in got[1:]]
    caps = [t[2] for t in got[1:]]
    assert rtols[0] == S.lin_rtol and caps[0] == S.lin_maxit_changing     # one change says nothing
    assert rtols[1] == pytest.approx(S.tighten_factor * S.lin_rtol, **ROUND)
    assert caps[1] == S.tighten_maxit_factor * S.lin_maxit_changing
    assert rtols[-1] == S.lin_rtol_min and caps[-1] == S.ksp_max_it
    assert all(a >= b for a, b in zip(rtols, rtols[1:])) and all(a <= b for a, b in zip(caps, caps[1:]))


def test_changing_cap_grows_above_the_measured_grids():
    """The changing steps' cap: lin_maxit_changing up to lin_maxit_n (2048), then x lin_maxit_growth
    (1.4) per doubling of N; tightening doubles the grid's own cap."""
    assert [S.maxit_changing(n) for n in (0, 64, 512, 2048, 4096, 8192)] == [40, 40, 40, 40, 56, 78]
    assert SolverSettings(lin_maxit_growth=2.0, lin_maxit_n=512).maxit_changing(2048) == 160
    for n, caps in ((2048, [40, 40, 80]), (4096, [56, 56, 112])):
        got = _run(StepPolicy(S, 1.0, n=n), [(1.0, -1, "free"), (2.0, 500, "free"), (0.5, 400, "contact")])
        assert [t[2] for t in got] == caps


def test_stalled_residual_tightens():
    p = StepPolicy(S, 1.0)
    got = _run(p, [(1.0, -1, "free"), (0.1, 500, "free"), (0.2, 10, "free")])
    assert got[2][0] == pytest.approx(S.tighten_factor * S.lin_rtol, **ROUND)


def test_users_petsc_options_decide():
    """own=False (the user gave -ksp_rtol, -snes_ksp_ew, ...): no tolerances, the history still kept."""
    p = StepPolicy(S, 1.0, own=False)
    assert _run(p, [(1.0, -1, "free"), (0.1, 5, "contact")]) == [None, None]
    assert p.changes == [-1, 5] and p.residuals == [1.0, 0.1]


def test_policy_reads_its_settings():
    s = SolverSettings(lin_rtol=0.3, first_rtol_factor=0.5, lin_maxit_changing=7, inner_atol_factor=2.0)
    first = StepPolicy(s, 1.0).step(-1, "contact")
    assert first == (pytest.approx(0.15, **ROUND), 2.0, 7)


@pytest.mark.parametrize("mode", ["contact", "free"])
def test_single_precision_floor_by_mode(mode):
    """A changing step solves in single precision while its rtol is at least the floor of its mode:
    single_rtol_min (1e-2) on the free set, single_rtol_min_contact (0: any rtol) on the contact set,
    whose flexible solve forms the solution from the preconditioned vectors; exact steps never."""
    p = StepPolicy(S, 1.0)
    singles = []
    for res, change in [(1.0, -1), (0.5, 1000), (0.4, 900), (0.3, 800), (0.2, 700), (0.1, 0)]:
        p.record_residual(res)
        rtol = p.step(change, mode)[0]
        singles.append((rtol, p.single))
    assert singles[-1] == (S.exact_rtol, False)
    floor = S.single_rtol_min_contact if mode == "contact" else S.single_rtol_min
    assert any(rtol < S.single_rtol_min for rtol, _ in singles[:-1])      # the wandering steps tightened
    assert [single for _, single in singles[:-1]] == [rtol >= floor for rtol, _ in singles[:-1]]
    if mode == "free":
        assert not all(single for _, single in singles[:-1])
    else:
        assert all(single for _, single in singles[:-1])
    off = StepPolicy(SolverSettings(changing_precision="double"), 1.0)
    off.step(-1, mode)
    assert not off.single


def test_mixed_steps():
    """The steps PETSc solves take mixed pairs while they must cut their residual by at most
    mixed_reduction_max: a changing step by 1 / rtol, an exact one by the latest measure over the
    tolerance; never float32-basis steps, never without a tolerance, never with the setting 0."""
    tol, top = 1e-8, S.mixed_reduction_max
    p = StepPolicy(SolverSettings(single_exact_reduction_max=0.0), 1.0, tol=tol)   # exact steps in PETSc
    p.record_residual(1.0)
    p.step(-1, "contact")
    assert p.single and not p.mixed                               # float32 basis: not a PETSc step
    p.record_residual(top * tol * 1.01)
    p.step(0, "contact")
    assert not p.mixed                                            # an exact step from too far out
    p.record_residual(top * tol * 0.99)
    p.step(0, "contact")
    assert p.mixed
    assert p.mixed_reduction(1e-3) == pytest.approx(1e3, **ROUND) and p.mixed_reduction(None) == 0.99 * top
    # tightened free-set steps (rtol < single_rtol_min: PETSc in float64 basis) by their rtol
    q = StepPolicy(SolverSettings(lin_rtol=1e-3), 1.0, tol=tol)
    q.record_residual(1.0)
    q.step(5, "free")
    assert not q.single and q.mixed
    q = StepPolicy(SolverSettings(lin_rtol=0.1 / top), 1.0, tol=tol)
    q.record_residual(1.0)
    q.step(5, "free")
    assert not q.single and not q.mixed                           # 10 x top
    for off in (StepPolicy(S, 1.0), StepPolicy(SolverSettings(mixed_reduction_max=0.0), 1.0, tol=tol)):
        off.record_residual(tol)
        off.step(0, "free")
        assert not off.mixed


@pytest.mark.parametrize("mode", ["contact", "free"])
def test_exact_steps_single(mode):
    """An exact step solves with a float32 basis (flexible, single.py) while it must cut its residual by
    at most single_exact_reduction_max (the latest measure over the tolerance), else in PETSc with
    mixed pairs or float64 ones; never on the free set once it cycles (the cycles' outer FGMRES keeps
    a float64 basis), never with the setting 0, never without a tolerance."""
    tol, top = 1e-8, S.single_exact_reduction_max
    assert top == S.mixed_reduction_max
    p = StepPolicy(S, 1.0, tol=tol)
    p.record_residual(top * tol * 1.01)
    p.step(0, mode)
    assert not p.single and not p.mixed
    p.record_residual(top * tol * 0.99)
    p.step(0, mode)
    assert p.single and not p.mixed
    p.cycling = True
    p.step(0, mode)
    assert p.single == (mode == "contact") and p.mixed == (mode == "free")
    for off in (StepPolicy(SolverSettings(single_exact_reduction_max=0.0), 1.0, tol=tol), StepPolicy(S, 1.0)):
        off.record_residual(tol)
        off.step(0, mode)
        assert not off.single
