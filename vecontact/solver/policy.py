"""Step policy of the inexact semismooth Newton method: pure rules (no PETSc, no MPI, no arrays).

Before every Newton step the solver (snes.py) asks where to solve the step's linear system
(``choose_step``: on the contact set or on the free set) and how tightly (``StepPolicy.step``), given
the active-set changes and the convergence measures of the iterates so far.  The constants are
SolverSettings fields (settings.py); what they were measured on is in benchmarks/RESULTS.md.

Tolerances (rtol, atol, max_it) of a step's Krylov solve:

* the first step of a grid level (change -1) decides the set the others refine: first_rtol_factor x
  lin_rtol, at most lin_maxit_changing iterations (more above lin_maxit_n: SolverSettings.maxit_changing);
* while the active set changes: lin_rtol, at most lin_maxit_changing iterations, both tightened
  (x tighten_factor down to lin_rtol_min, x tighten_maxit_factor up to ksp_max_it) whenever
  ``tighten_steps`` says the steps make too little progress;
* once the set stopped changing the step is the solution (PDAS converges in one more step): exact_rtol,
  ksp_max_it iterations (cycle_max_it on the free set once ``cycling``), and the absolute tolerance
  decides.  atol = tol / kappa bounds the free-set
  residual in h_rms (its 2-norm bounds the max-norm measure); a contact-set step's residual is a gap
  error on C whose image under m is what the measure sees, hence inner_atol_factor x atol.  If an exact
  step on an unchanged set still did not converge, atol x atol_retry_factor.  The 2-norm atol is a
  cap: the measure stop (measurestop.py) usually ends an exact step well before it.

A changing step solves in single precision (``single``, single.py; changing_precision) while its rtol
is at least the floor of its mode: single_rtol_min on the free set (tighter, a float32 basis left the
next iterate less accurate), single_rtol_min_contact (0) on the contact set, whose flexible solve forms
the solution from the preconditioned vectors, not from the float32 basis [RESULTS.md].

An exact step solves with a float32 basis too, flexible (FGMRES: the solution formed from the
preconditioned vectors; on the free set as well), while it must cut its residual by at most
single_exact_reduction_max (``mixed_reduction``), except on the free set once it cycles; the measure
stop watches it as it watches PETSc's solves.  A step PETSc solves (the other exact ones, or tightened
below that floor) forms its operator's products with a float32 backward transform (``mixed``,
subset.Mixed) while it must cut its residual by at most mixed_reduction_max: such a solve stalls near
1e-7 of its start (the float32 rounding of A z), and the Newton residual that judges it is formed in
float64.

After a changing step on the free set the iterate is smoothed (``sweeps``, SolverSettings.step_sweeps:
projected Richardson sweeps, warmstart.smooth_gap; the finest grid's solve only, contact.py gives the
coarse ones 0): the loose solve leaves short-wave errors at the contact edges that would flip points in
the next step [RESULTS.md].  Not after an exact step (it is the solution once its set is right), nor
after a contact-set step, whose iterate has no pressure on F: the sweeps give it some, and the set
then wanders [RESULTS.md].

Free-set steps start as plain GMRES; after a changing free-set step that used the whole of an iteration
cap of at least SolverSettings.cycle_cap (a tightened cap; the first one on grids of high stiffness
range) they run as FGMRES over GMRES(free_cycle) cycles (``cycling``, ``record_iterations``).
"""
from __future__ import annotations

__all__ = ["StepPolicy", "tighten_steps", "choose_step"]


def tighten_steps(changes, residuals, wander_ratio):
    """True when the inexact Newton steps must be solved tighter.

    ``changes``: active-set changes per Newton step (-1 for the first); ``residuals``: the convergence
    measure per iterate.  Tighten when the set changes shrink by less than 1 / wander_ratio per step
    (this includes growing: the steps' errors flip points, more so at large N and v), or when the
    residual did not fall (the first step often overshoots, hence from the third iterate on).
    """
    wandering = len(changes) >= 3 and changes[-2] > 0 and changes[-1] > wander_ratio * changes[-2]
    stalled = len(residuals) >= 3 and residuals[-1] >= residuals[-2]
    return wandering or stalled


def choose_step(requested, n_active, n_points, area):
    """"contact" (solve the step on the contact set) or "free" (on the free set).

    ``requested``: the contact_step setting (auto, contact, free); auto takes contact-set steps while
    the active set has at most ``area`` x ``n_points`` of the grid's points."""
    if requested != "auto":
        return requested
    return "contact" if n_active <= area * n_points else "free"


class StepPolicy:
    """Krylov tolerances of the Newton steps of one SNES solve (see the module docstring).

    ``atol``: the absolute tolerance of an exact free-set step (tol / kappa, h_rms units); ``own``: False
    when the user's PETSc options (-ksp_rtol, -snes_ksp_ew, ...) decide the tolerances instead;
    ``stiffness_range``: max|m_q|/min|m_q| of the grid (ContactOperator.stiffness_range), which sets
    when the free-set steps start their cycles; ``n``: the grid's N, which sets the changing steps'
    iteration cap (SolverSettings.maxit_changing; 0: lin_maxit_changing).
    ``changes`` and ``residuals`` keep the history the rules read (and the solver reports).
    """

    def __init__(self, settings, atol, own=True, tol=None, stiffness_range=0.0, n=0):
        self.settings = settings
        self.cycle_cap = settings.cycle_cap(stiffness_range)   # record_iterations
        self.tol = tol             # the solve's convergence tolerance (mixed: None, never)
        self.own = own
        self.lin_rtol = settings.lin_rtol
        self.atol = atol
        self.maxit_changing = settings.maxit_changing(n)
        self.changes = []
        self.residuals = []
        self.single = False        # the latest step solves in single precision (single.py)
        self.mixed = False         # ... else in PETSc, its operator with mixed pairs (mixed_reduction)
        self.cycling = False       # free-set steps as FGMRES over GMRES cycles from now on (record_iterations)
        self.sweeps = 0            # smoothing sweeps on the iterate the latest step makes (snes.py)
        self.returned = False      # an iterate came back to the one two steps before (record_residual)
        self._last = None          # (mode, change, cap) of the latest step

    def record_residual(self, residual):
        """The convergence measure of the latest iterate.  A measure that repeats the one two iterates
        back (to step_return_rtol) marks a return: the smoothed steps flip the same points to and fro;
        no sweeps from then on (``sweeps``)."""
        r = self.residuals
        r.append(residual)
        rtol = self.settings.step_return_rtol
        if rtol and len(r) >= 3 and abs(r[-1] - r[-3]) <= rtol * r[-1]:
            self.returned = True

    def record_iterations(self, iterations):
        """Krylov iterations of the latest step.  A changing free-set step that used the whole of a cap
        of at least ``cycle_cap`` (SolverSettings.cycle_cap of the grid's stiffness range: a tightened
        cap, or the first one at high range) announces long solves, where the plain GMRES basis costs
        more orthogonalisation than the extra iterations of FGMRES over GMRES(free_cycle) cycles:
        ``cycling`` turns on for the rest of the solve.  Solves whose steps stay under the first caps (slow sliding) keep plain GMRES, where the
        cycles lose [RESULTS.md]."""
        s = self.settings
        if self._last is None or s.free_cycle == 0:
            return
        mode, change, cap = self._last
        if mode == "free" and change != 0 and cap >= self.cycle_cap and iterations >= cap:
            self.cycling = True

    def step(self, change, mode):
        """(rtol, atol, max_it) of the next step's Krylov solve, or None when ``own`` is False.

        ``change``: how many points the active set changed by in this Newton step (-1: first step);
        ``mode``: where the step is solved (choose_step)."""
        s = self.settings
        ch = self.changes
        ch.append(change)
        self.sweeps = s.step_sweeps if mode == "free" and change != 0 and not self.returned else 0
        if not self.own:
            return None
        if change == 0 and len(ch) >= 2 and ch[-2] == 0:
            # the previous step was already exact on this set and did not converge: the 2-norm
            # tolerance was too loose for the max-norm measure
            self.atol *= s.atol_retry_factor
        if tighten_steps(ch, self.residuals, s.wander_ratio):
            self.lin_rtol = max(s.tighten_factor * self.lin_rtol, s.lin_rtol_min)
            self.maxit_changing = min(s.tighten_maxit_factor * self.maxit_changing, s.ksp_max_it)
        atol = self.atol * (s.inner_atol_factor if mode == "contact" else 1.0)
        self.single = False
        if change == 0:
            cap = s.cycle_max_it if self.cycling and mode == "free" else s.ksp_max_it
            self._last = (mode, change, cap)
            reduction = self.mixed_reduction(None)
            # not inside the free set's cycles, whose outer FGMRES keeps its basis in float64
            self.single, self.mixed = s.step_precision(reduction, not (self.cycling and mode == "free"))
            return s.exact_rtol, atol, cap
        rtol = s.first_rtol_factor * self.lin_rtol if change < 0 else self.lin_rtol
        cap = min(s.ksp_max_it, self.maxit_changing)
        floor = s.single_rtol_min_contact if mode == "contact" else s.single_rtol_min
        self.single = s.changing_precision == "single" and rtol >= floor
        self.mixed = not self.single and self.mixed_reduction(rtol) <= s.mixed_reduction_max
        self._last = (mode, change, cap)
        return rtol, atol, cap

    def mixed_reduction(self, rtol):
        """The factor by which the next step must cut its residual: 1 / ``rtol`` for a changing step,
        for an exact one (rtol None) the latest measure over the tolerance (inf when unknown).  A
        solve whose operator takes mixed pairs stalls near 1e-7 of its start (float32 rounding of A z),
        so it takes them only up to mixed_reduction_max [RESULTS.md]."""
        if rtol is not None:
            return 1.0 / rtol
        if self.tol is None or not self.residuals:
            return float("inf")
        return self.residuals[-1] / self.tol
