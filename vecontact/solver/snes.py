"""Matrix-free PETSc SNES solve of the contact NCP in the gap formulation.

Unknown: the nondimensional gap g^ >= 0 (units h_rms), pressure p^(g^) = 1 + m (g^ + h^) (units sigma0).
m has no q = 0 mode, so mean(p^) = 1 for every iterate: load control for free, no extra unknown.
NCP:  g^ >= 0,  p^ >= 0,  g^ p^ = 0.

Default method: semismooth Newton (= primal-dual active set) on the min-residual
    F(g^) = min(g^, p^(g^) / kappa)           (kappa = k ell / sigma0, see operator.py)
with SNES newtonls + basic (full-step) line search.  Active (contact) set C = {p^ >= kappa g^} of the
current iterate (newton.py), free set F its complement.  Generalised Jacobian (Python Mat, one FFT pair)
    J x = P_C x + P_F m x / kappa.
Before every step the step policy (policy.py) decides where its linear system is solved, from the size of
the contact set (SolverSettings.contact_step / contact_step_area), and how tightly:
* on the contact set (contactset.py): KSP ``preonly`` with a Python PC that eliminates the free set
  exactly and runs an inner FGMRES (options prefix ``contact_``) on the restricted compliance;
  cheap orthogonalisation (vectors of A/A0 N^2 entries), 2 FFT pairs per inner iteration;
* on the free set (freeset.py): KSP ``preonly`` with a Python PC that sets x_C = r_C and runs an
  inner GMRES (the SNES's own prefix: ``-ksp_*``) on the stiffness of the free set, preconditioned by
  its compliance; vectors of (1 - A/A0) N^2 entries, 2 FFT pairs per inner iteration.
After a free-set step whose set changed, the line search's pre-check smooths the next iterate
(NewtonState.smooth_step, SolverSettings.step_sweeps).
The Krylov tolerances are loose while the active set changes and exact once it stops (policy.py); an
exact step's solve also ends as soon as its update meets the convergence test (measurestop.py); a
changing step solves with a float32 Krylov basis (single.py, SolverSettings.changing_precision), an
exact one too near the solution (single_exact_reduction_max);
``-snes_ksp_ew`` or any ``-ksp_``/``-contact_ksp_`` rtol, atol or max_it in the options hand them to
PETSc instead (with ``-snes_ksp_ew`` each step's inner solve takes the rtol PETSc's Eisenstat-Walker
forcing sets on the outer KSP; it diverged at fast sliding, benchmarks/RESULTS.md).  Convergence is
decided by our own scale-free test (operator.py), installed with SNESSetConvergenceTest.
``-snes_type vinewtonrsls`` selects PETSc's reduced-space VI method (vi.py).  Every constant:
settings.py; the measurements behind them: benchmarks/RESULTS.md.
"""
from __future__ import annotations

import gc
import time

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from vecontact.solver.contactset import ContactSetStep
from vecontact.solver.freeset import FreeSetStep
from vecontact.solver.measurestop import MeasureStop
from vecontact.solver.newton import NewtonState
from vecontact.solver.policy import StepPolicy, choose_step
from vecontact.solver.settings import PETSC_DEFAULTS, PETSC_GLOBAL_DEFAULTS, PETSC_VI_DEFAULTS
from vecontact.solver.subset import Workspace, counters
from vecontact.solver.vi import ViNewton

__all__ = ["ncp_solve", "petsc", "hold_comm", "check_options", "POLICY_OFF"]

_PETSC = None
_ANCHORS = {}

# PETSc options with which the user, not StepPolicy, sets the Newton steps' Krylov tolerances
POLICY_OFF = ("snes_ksp_ew", "ksp_rtol", "ksp_atol", "ksp_max_it",
              "contact_ksp_rtol", "contact_ksp_atol", "contact_ksp_max_it")


def petsc():
    """Import petsc4py lazily (after mpi4py), initialising PETSc once."""
    global _PETSC
    if _PETSC is None:
        from petsc4py import PETSc
        _PETSC = PETSc
    return _PETSC


def hold_comm(comm):
    """Keep one PETSc object on ``comm`` for the life of the process (collective on its first call).

    PETSc duplicates a communicator (a collective call) when the first object on it is created and
    frees the duplicate when the last one is destroyed.  Python destroys petsc4py objects at
    rank-dependent times, so one rank could duplicate again while the other still held an object: a
    2-rank deadlock (2048^2 benchmark).  With this anchor the duplicate is made once."""
    if comm.size > 1 and id(comm) not in _ANCHORS:
        _ANCHORS[id(comm)] = (comm, petsc().Vec().createMPI((1, comm.size), comm=comm))


def _reason_name(cls, value):
    for k in dir(cls):
        if not k.startswith("_") and getattr(cls, k) == value:
            return k
    return str(value)


class _Semismooth:
    """SNES callbacks of F(g^) = min(g^, p^/kappa) and the Python Mat context of its generalised
    Jacobian J x = P_C x + P_F m x / kappa.  Before each Newton step ``jacobian`` moves the state to the
    new active set, lets the policy choose the step solver and its tolerances, and hands both over."""

    def __init__(self, state, policy, steps, settings, stop):
        self.state = state
        self.policy = policy
        self.steps = steps                       # {"contact": ContactSetStep, "free": FreeSetStep}
        self.stop = stop                         # MeasureStop of the exact steps, or None
        self.settings = settings
        self.mode = None                         # where the current step is solved
        self.modes = []                          # (Newton step, mode) at every switch
        self.lin_history = []                    # linear iterations before each Newton step
        self.smoothed = 0                        # Newton steps whose iterate was smoothed (precheck)
        self.edge_used = False                   # a contact-set step ran with an edge term (edge.py)
        self.edge_step = False                   # the latest step did
        self.ksp = None

    def configure(self, snes, X):
        self.ksp = snes.getKSP()
        self.ksp.getPC().setPythonContext(self.steps["contact"])
        snes.setLineSearchPreCheck(self.precheck)

    def precheck(self, X, Y, snes=None):
        """PETSc's hook between a step and its line search: with the policy's ``sweeps`` the step Y from X
        becomes X - S(X - Y), the smoothed iterate (NewtonState.smooth_step).  Returns whether Y changed."""
        sweeps = self.policy.sweeps
        if not sweeps:
            return False
        st = self.state
        st.smooth_step(st.view(X), st.view(Y, readonly=False), sweeps, self.settings.smooth_ratio)
        self.smoothed += 1
        return True

    def residual(self, snes, X, F):
        st = self.state
        st.ensure(st.view(X))
        out = np.divide(st.p, st.kappa, out=st.view(F, readonly=False))    # no temporary
        np.minimum(st.g, out, out=out)

    def jacobian(self, snes, X, J, P):
        st = self.state
        st.ensure(st.view(X))
        change = st.update_active_set()
        self.lin_history.append(self.linear_iterations(snes))
        mode = choose_step(self.settings.contact_step, st.nact, st.n_points,
                           self.settings.step_area(st.op.modulus_range(), st.op.N))
        step = self.steps[mode]
        if mode != self.mode:
            step.activate(self.ksp)
            self.mode = mode
            self.modes.append((len(self.lin_history) - 1, mode))
        step.set_active(st.act, st.nact)
        self.edge_step = getattr(step, "edge", None) is not None
        self.edge_used = self.edge_used or self.edge_step
        step.carry(change == 0)
        if len(self.lin_history) >= 2:
            self.policy.record_iterations(self.lin_history[-1] - self.lin_history[-2])
        tolerances = self.policy.step(change, mode)
        if self.policy.cycling and mode == "free":
            step.start_cycles()
        if tolerances is not None:
            step.set_tolerances(*tolerances, single=self.policy.single, mixed=self.policy.mixed, flexible=change == 0)
        if self.stop is not None and change == 0:
            self.stop.arm(self.policy.residuals[-1])
        elif self.stop is not None:
            self.stop.disarm()

    def mult(self, mat, x, y):
        st = self.state
        xa = st.view(x)
        ya = st.view(y, readonly=False)
        st.fft.apply(xa, st.op.m, ya, 1.0 / st.kappa)     # m x / kappa on every point
        np.copyto(ya, xa, where=st.act)      # identity rows on the contact set

    def linear_iterations(self, snes):
        """Inner Krylov iterations so far: every Newton step is solved by a step's inner KSP (the outer
        KSP is ``preonly``), so the steps' own counts are the whole (``snes``: the interface of vi.py)."""
        return sum(s.iterations for s in self.steps.values())

    def diagnostics(self, linear_iterations):
        """Active-set changes, linear iterations before each step (and at the end), step-mode switches."""
        return dict(nchg=self.policy.changes, lin_history=self.lin_history + [linear_iterations], modes=self.modes,
                    measure_checks=self.stop.trace if self.stop is not None else [],
                    smoothed_steps=self.smoothed, **counters(self.steps.values()))

    def release(self):
        for step in self.steps.values():
            step.release()
        if self.stop is not None:
            self.stop.release()
        self.ksp = None


class _Convergence:
    """Our scale-free convergence test (operator.py measures <= tol), installed on the SNES."""

    def __init__(self, state, policy, tol, monitor, form=None, settings=None, stall_above=0.0):
        self.state = state
        self.policy = policy
        self.tol = tol
        self.monitor = monitor
        self.history = []      # (iteration, measure, FFT transforms so far)
        self.form = form                        # its edge_used (_Semismooth; the VI form has none)
        self.settings = settings                # edge_newton_max, edge_capped_max, ksp_max_it, *_stall
        self.edge_capped = 0                    # Newton steps in a row with the term that used all of ksp_max_it
        self.edge_stalled = False
        self.lowest = (np.inf, 1)               # the lowest measure since the first step, and its iteration
        self.recent = []                        # the last cycle_period measures before this one
        self.stall_above = stall_above          # a coarse grid's: coarse_stall counts while the lowest is above

    def __call__(self, snes, it, norms):
        PETSc = petsc()
        st = self.state
        st.ensure(st.view(snes.getSolution()))
        meas = st.measures()
        res = max(meas)
        self.history.append((it, res, st.fft.transforms))
        if self.policy is not None:
            self.policy.record_residual(res)
        elif isinstance(self.form, ViNewton):
            self.form.iterate(snes, res)        # its next step's Krylov rtol (vi.py)
        if self.monitor is not None:
            self.monitor(it, res, meas)
        if res <= self.tol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        if not np.isfinite(res):
            return PETSc.SNES.ConvergedReason.DIVERGED_FNORM_NAN
        if self._edge_stalled(snes, it):
            self.edge_stalled = True    # solved again without the term (ncp_solve)
            return PETSc.SNES.ConvergedReason.DIVERGED_USER
        if self._measure_stalled(it, res):
            # full steps that stopped gaining: with the term, solved again without it; without, with the
            # fallback's line search (ncp_solve)
            self.edge_stalled = bool(getattr(self.form, "edge_used", False))
            return PETSc.SNES.ConvergedReason.DIVERGED_USER
        if self._coarse_stalled(it):
            return PETSc.SNES.ConvergedReason.DIVERGED_USER     # to the fallback, with the term or not
        if it >= snes.getTolerances()[3]:
            return PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT
        return PETSc.SNES.ConvergedReason.ITERATING

    def _measure_stalled(self, it, res):
        """Whether the measure has not reached a new lowest in the last SolverSettings.fallback_stall Newton
        iterations, or edge_stall while the edge term is in use (fallback_stall 0: never), counted from
        the first step's: a good start (a coarse grid's) can measure lower than the steps that must first
        move its set (64^2, sharp rubber: 8.4, then 129, 25, ... converging at 26).  The paper's finest
        grids go at most 3 without a new lowest; full steps that fail go 13-20 by their 20th iteration
        (RESULTS.md, "`fallback_stall`"); with the term, 10 lost on the sharp rubber at 10 m/s.
        Or whether the measure came back to within cycle_rtol of one 2 to cycle_period iterates before,
        the last one differing: full steps that cycle never converge, and a cycle's new lowests by 1e-9
        kept the count from firing (RESULTS.md, "`cycle_rtol`").  The VI method's attempts (the fallback's
        or the user's) count to vi_stall instead: its 145 converging attempts went at most 8 iterations
        without a new lowest, a failing one ran its 300 (RESULTS.md, "`vi_stall`")."""
        if it >= 1 and res < self.lowest[0]:
            self.lowest = (res, it)
        s = self.settings
        if isinstance(self.form, ViNewton):     # the VI method: its own count, no cycles looked for
            return bool(s is not None and s.vi_stall and it - self.lowest[1] >= s.vi_stall)
        n = getattr(s, "fallback_stall", 0)
        if not n:
            return False
        if getattr(self.form, "edge_used", False):
            n = s.edge_stall
        # a return: the measure back to one 2..cycle_period iterates before, the last differing (a plateau
        # that creeps, 13.1731, 13.1713, 13.1714, 13.1709 ..., can still get out: 64^2, sharp rubber)
        near = [abs(res - r) <= s.cycle_rtol * res for r in self.recent]
        cycled = s.cycle_rtol > 0 and len(near) >= 2 and not near[-1] and any(near[:-1])
        self.recent = (self.recent + [res])[-s.cycle_period:]
        return bool(cycled or (n and it - self.lowest[1] >= n))

    def _coarse_stalled(self, it):
        """Whether a coarse grid's full steps (``stall_above`` > 0: ncp_solve's fallback_above) have reached
        no new lowest in SolverSettings.coarse_stall Newton iterations while that lowest is above
        ``stall_above``: they wander, and would take the fallback after coarse_max_it anyway
        (RESULTS.md, "`coarse_stall`").  After _measure_stalled, which keeps the lowest."""
        s = self.settings
        return bool(self.stall_above > 0 and s is not None and s.coarse_stall and not isinstance(self.form, ViNewton)
                    and self.lowest[0] > self.stall_above and it - self.lowest[1] >= s.coarse_stall)

    def _edge_stalled(self, snes, it):
        """Whether the solve, not converged after Newton iteration ``it``, stalls on the edge term: it ran
        with the term and reached edge_newton_max iterations, or its last edge_capped_max steps each ran
        with the term and used the whole ksp_max_it (the steps' mark of an indefinite preconditioner;
        the paper's contact-set steps never used it all, RESULTS.md; not counted when the user sets the
        steps' Krylov tolerances, POLICY_OFF)."""
        s, form = self.settings, self.form
        if s is None or not getattr(form, "edge_used", False):
            return False
        if it > 0 and form.lin_history and self.policy.own:
            last = form.linear_iterations(snes) - form.lin_history[-1]
            self.edge_capped = self.edge_capped + 1 if form.edge_step and last >= s.ksp_max_it else 0
        return bool((s.edge_newton_max and it >= s.edge_newton_max)
                    or (s.edge_capped_max and self.edge_capped >= s.edge_capped_max))


def check_options(options, key="numerics.petsc"):
    """Let PETSc read the user's ``options`` (a parsed dict, options.py) on a throwaway SNES and on an
    inner KSP under the contact-set steps' prefix, on this rank alone, so that a value PETSc refuses
    (a negative restart, an unknown KSP type, a word for a number) is an OptionError before
    any case starts, instead of a PETSc traceback in the first one.  Nothing is left in the options
    database."""
    from vecontact.solver.options import OptionError, solver_items
    PETSc = petsc()
    prefix = "vecontact_check_"
    keys = _apply_options(PETSc, prefix, {}, solver_items(options)[0])
    objs = []
    try:
        for obj, own in ((PETSc.SNES(), ""), (PETSc.KSP(), "contact_")):
            objs.append(obj.create(comm=PETSc.COMM_SELF))
            obj.setOptionsPrefix(prefix + own)
            obj.setFromOptions()
    except PETSc.Error as exc:
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        raise OptionError(key, f"PETSc refuses it: {lines[-1].removeprefix('[0]').strip()}") from None
    finally:
        for obj in objs:
            obj.destroy()
        _remove_options(PETSc, keys)


def _apply_global_options(PETSc, user):
    """PETSC_GLOBAL_DEFAULTS (or the user's value of those keys) without the solver prefix; a value
    already in the database (PETSC_OPTIONS) beats the default."""
    opts = PETSc.Options()
    for k, v in PETSC_GLOBAL_DEFAULTS.items():
        if k in user:
            opts[k] = user[k]
        elif not opts.hasName(k):
            opts[k] = v


def _apply_options(PETSc, prefix, defaults, user):
    """Put ``defaults`` (unless the user gives them) and the user's options into the options database
    under ``prefix``; returns the keys set (to remove them after the solve)."""
    opts = PETSc.Options()
    items = dict(defaults)
    items.update((k, v) for k, v in user.items() if k not in PETSC_GLOBAL_DEFAULTS)
    for k, v in items.items():
        opts[prefix + k] = v
    return [prefix + k for k in items]


def _remove_options(PETSc, keys):
    """Take the keys _apply_options set out of the options database again."""
    opts = PETSc.Options()
    for k in keys:
        opts.delValue(k)


_COUNTER = [0]


def ncp_solve(op, g0, tol, max_it, settings, options=None, monitor=None, direct=False, fallback_above=0.0):
    """Solve the NCP of ``op`` (ContactOperator) from the nondimensional gap ``g0``.

    ``settings``: SolverSettings; ``options``: PETSc's entries of a parsed options dict (options.py),
    put into the database under a solver prefix of their own; ``max_it``: Newton iterations.
    Returns (ghat, phat, active, info); info has iterations, linear_iterations, converged, reason,
    residual, measures, history, nchg, lin_history, modes, seconds, snes_type, ksp_type.
    A solve not converged after SolverSettings.edge_newton_max Newton iterations with the contact-set
    steps' edge term, or whose last edge_capped_max steps with the term each used the whole ksp_max_it,
    starts again from ``g0`` without it; info's iterations, linear_iterations and seconds then count
    both attempts, and info["edge_retry"] holds the first one's (iterations, linear_iterations,
    residual, seconds); the other entries are the second attempt's.  A solve still not converged, or
    whose measure reached no new lowest in fallback_stall Newton iterations (with the term in use:
    edge_stall, and the retry without it first), starts again from ``g0`` by SolverSettings.fallback
    (unless the user chose a line search or the VI method): "vi", PETSc's reduced-space VI Newton
    (vi.py); or a PETSc line search on the full steps (without the term if it was retried), then full
    steps from that attempt's last iterate to ``max_it`` if it stopped short.  The fallback's own
    attempt runs to SolverSettings.fallback_max_it.  All count, info["fallback_retry"] holds the full
    steps' attempt, and info["edge_retry"] their retry if there was one.  With ``direct`` (a coarser
    grid of the same solve needed the fallback: contact.py) the solve skips the full steps and starts
    with the fallback's attempt (info["fallback_direct"] True), if there is one; if that attempt fails,
    the ordinary attempts follow from ``g0`` with bt as the fallback (vi) or none (a line search),
    info["direct_retry"] holding the first, and without ``fallback_above``: after a failed VI attempt bt
    is the last resort, and full steps left to run to max_it converged where the coarse stall rule would
    have handed over to it (RESULTS.md, "`coarse_stall`"); a failed VI attempt after failed full steps is
    followed by bt from ``g0`` (info["vi_retry"] holding it).  Full steps whose last measure is at most
    ``fallback_above`` (a coarse grid that nearly converged) take no fallback; where there is one, they
    end once their measure has reached no new lowest in SolverSettings.coarse_stall Newton iterations
    while that lowest is above ``fallback_above`` (a coarse grid that wanders; contact.py).
    """
    # what is alive now is not the solve's: frozen, the collection that ends it walks only what the
    # solve made (the whole heap took 22 ms, 7 % of a 1.7 s solve at 1024^2; RESULTS.md).  Not when
    # the caller froze objects itself: unfreeze would thaw theirs.
    thaw = gc.get_freeze_count() == 0
    if thaw:
        gc.freeze()
    try:
        method = settings.fallback
        opts = dict(options or {})
        fallback = not (method == "none" or "snes_linesearch_type" in opts or _is_vi(opts))
        if direct and fallback:
            again = _fallback_attempts(op, g0, tol, max_it, settings, opts, False, monitor)
            again[3]["fallback_direct"] = True
            if again[3]["converged"]:
                return again
            # the VI method on a large contact set can stall where full steps and bt converge (the SLS at
            # 1 mm/s, 29 %, in a warm-started chain: RESULTS.md): the ordinary attempts from g0, bt the fallback,
            # with no coarse floor (bt is the last resort: the full steps run on)
            later = ncp_solve(op, g0, tol, max_it, replace(settings, fallback="bt" if method == "vi" else "none"),
                              options, monitor)
            later[3]["fallback_direct"] = True
            return _after(again[3], later, "direct_retry")
        # the stall rule hands over to the fallback: none without it
        g, p, act, info = _edge_attempts(op, g0, tol, max_it, settings if fallback else
                                         replace(settings, fallback_stall=0), options, monitor,
                                         stall_above=fallback_above if fallback else 0.0)
        if info["converged"] or not fallback or info["residual"] <= fallback_above:
            return g, p, act, info
        # full steps of the primal-dual active-set method have no convergence guarantee for a
        # non-symmetric m (the SLS rubber at 1 mm/s wanders for ever, RESULTS.md): the solve starts
        # again from g0, and every attempt counts
        edge_retried = bool(info.get("edge_retry"))
        again = _fallback_attempts(op, g0, tol, max_it, settings, opts, edge_retried, monitor)
        if not again[3]["converged"] and method == "vi":
            # the VI method failed (it stalled, vi_stall, or ran out): bt on the full steps from g0,
            # as after a failed direct attempt
            later = _fallback_attempts(op, g0, tol, max_it, replace(settings, fallback="bt"), opts, edge_retried,
                                       monitor)
            again = _after(again[3], later, "vi_retry")
        if "edge_retry" in info:        # the full steps' retry without the term
            again[3].setdefault("edge_retry", info["edge_retry"])
        return _after(info, again, "fallback_retry")
    finally:
        if thaw:
            gc.unfreeze()


def _fallback_attempts(op, g0, tol, max_it, settings, opts, edge_retried, monitor):
    """The fallback's attempt from ``g0`` (ncp_solve), by SolverSettings.fallback, to fallback_max_it and
    without the stall rule: the VI method with bt, or a line search on the full steps (without the
    edge term if the full steps had to drop it: ``edge_retried``) and full steps after it."""
    method = settings.fallback
    settings = replace(settings, fallback_stall=0)
    # its measure falls slowly but steadily: the 2048^2 sharp rubber's bt needed 126 (RESULTS.md)
    fb_it = settings.fallback_max_it
    # a step whose line search fails still moves the iterate (snes_max_fail): bt stopped otherwise
    lsopts = dict({"snes_max_fail": str(fb_it)}, **opts, snes_linesearch_type="bt" if method == "vi" else method)
    if method == "vi":
        # its steps project the gap onto g >= 0; with full steps it wandered in 2 of 5 solves at 256^2,
        # with bt it converged in all (RESULTS.md, "`fallback`"); it has no edge term to retry without
        return _edge_attempts(op, g0, tol, fb_it, settings, dict(lsopts, snes_type="vinewtonrsls"), monitor)
    return _linesearch_attempts(op, g0, tol, fb_it, max_it, replace(settings, edge_window=0) if edge_retried
                                else settings, opts, lsopts, monitor)


def _linesearch_attempts(op, g0, tol, fb_it, max_it, settings, opts, lsopts, monitor):
    """The fallback by a line search on the full steps from ``g0`` (ncp_solve; ``lsopts``: ``opts`` with
    it) to ``fb_it``, then full steps from its last iterate if it stopped short, to ``max_it`` (the
    settings without the edge term when it stalled the full steps: with it the attempt stalled again
    in 7 of 10 such solves, RESULTS.md)."""
    again = _edge_attempts(op, g0, tol, fb_it, settings, lsopts, monitor)
    if again[3]["converged"]:
        return again
    # the line search can end its solve just short of tol (cp on the SLS rubber: 1.1-5.2e-8 for 1e-8,
    # RESULTS.md): full steps from its last iterate, which they then converge from
    return _after(again[3], _edge_attempts(op, again[0], tol, max_it, settings, opts, monitor))


def _edge_attempts(op, g0, tol, max_it, settings, options, monitor, stall_above=0.0):
    """_ncp_solve, and once more from ``g0`` without the edge term if it stalled on it (ncp_solve);
    ``stall_above``: _Convergence's (a coarse grid's full steps)."""
    g, p, act, info = _ncp_solve(op, g0, tol, max_it, settings, options, monitor, stall_above)
    if not info.pop("edge_stalled"):
        return g, p, act, info
    # stalled with the edge term (_Convergence._edge_stalled): it can make the contact-set steps'
    # preconditioner indefinite (edge.py); m_CC alone cannot, so the solve starts again from g0
    # without it, and both attempts count
    again = _ncp_solve(op, g0, tol, max_it, replace(settings, edge_window=0), options, monitor, stall_above)
    again[3].pop("edge_stalled")
    return _after(info, again, "edge_retry")


def _after(first, again, key=None):
    """The attempt ``again`` (g, p, act, info) made after the one whose info is ``first``: its info
    counts both in iterations, linear_iterations and seconds, and holds the first one's (iterations,
    linear_iterations, residual, seconds) under ``key`` (if given)."""
    info = again[3]
    if key is not None:
        info[key] = {k: first[k] for k in ("iterations", "linear_iterations", "residual", "seconds")}
    for k in ("iterations", "linear_iterations", "seconds"):
        info[k] += first[k]
    return again


def _is_vi(options):
    """Whether the user's PETSc options choose PETSc's VI method (vi.py) instead of ours."""
    return options.get("snes_type", PETSC_DEFAULTS["snes_type"]).startswith("vi")


def _ncp_solve(op, g0, tol, max_it, settings, options, monitor, stall_above=0.0):
    PETSc = petsc()
    options = dict(options or {})
    fft = op.fft
    comm = fft.comm
    nloc = int(np.prod(fft.local_real_shape))
    ntot = fft.N * fft.N
    vi = _is_vi(options)
    defaults = dict(PETSC_DEFAULTS)
    if vi:   # a user's -ksp_type runs on the reduced whole-grid vectors (FGMRES: 2 a Krylov iteration)
        restart = comm.allreduce(settings.restart(nloc, vectors=2), op=MPI.MIN)
        defaults.update(PETSC_VI_DEFAULTS, ksp_max_it=str(settings.ksp_max_it), ksp_gmres_restart=str(restart))
    hold_comm(comm)
    _COUNTER[0] += 1
    prefix = f"vecontact{_COUNTER[0]}_"
    state = NewtonState(op)
    if vi:
        policy = None
        # its steps on the contact set, without the edge term: with it they stalled (RESULTS.md)
        form = ViNewton(state, PETSc, ContactSetStep(op, state.kappa, PETSc, prefix, replace(settings, edge_window=0),
                                                      Workspace(fft)))
    else:
        # the atol bounds the max-norm measure: tol / kappa (see policy.py)
        policy = StepPolicy(settings, tol / state.kappa, own=not any(k in options for k in POLICY_OFF),
                            tol=tol, stiffness_range=op.stiffness_range(), n=op.N)
        work = Workspace(fft)            # both step types' whole-grid arrays, held once
        steps = dict(contact=ContactSetStep(op, state.kappa, PETSc, prefix, settings, work),
                     free=FreeSetStep(op, state.kappa, PETSc, prefix, settings, work))
        steps["contact"].advance = state.advance      # its residual without an FFT pair
        for step in steps.values():
            step.forcing = "snes_ksp_ew" in options     # EW sets the outer KSP's rtol; the steps pass it on
        stop = None
        if policy.own and settings.measure_stop == "on":
            stop = MeasureStop(state, tol, PETSc)
            for step in steps.values():
                stop.attach(step)
        form = _Semismooth(state, policy, steps, settings, stop)
    conv = _Convergence(state, policy, tol, monitor, form, settings, stall_above)
    _apply_global_options(PETSc, options)
    keys = _apply_options(PETSc, prefix, defaults, options)
    snes = X = Fv = J = None
    try:
        X = PETSc.Vec().createMPI((nloc, ntot), comm=comm)
        X.getArray()[:] = np.asarray(g0, dtype=float).ravel()
        Fv = X.duplicate()
        J = PETSc.Mat().createPython(((nloc, ntot), (nloc, ntot)), context=form, comm=comm)
        J.setUp()
        snes = PETSc.SNES().create(comm=comm)
        snes.setOptionsPrefix(prefix)
        snes.setFunction(form.residual, Fv)
        snes.setJacobian(form.jacobian, J, J)
        snes.getKSP().getPC().setType("python")
        form.configure(snes, X)
        snes.setTolerances(max_it=int(max_it))
        snes.setConvergenceTest(conv)
        snes.setFromOptions()
        t0 = time.perf_counter()
        snes.solve(None, X)
        reason = _reason_name(PETSc.SNES.ConvergedReason, snes.getConvergedReason())
        lits = form.linear_iterations(snes)
        state.ensure(X.getArray(readonly=True).reshape(fft.local_real_shape))
        act = state.contact_set()
        meas = state.measures(act)
        res = max(meas)
        converged = bool(res <= tol)
        info = dict(iterations=int(snes.getIterationNumber()), linear_iterations=int(lits), converged=converged,
                    reason="converged" if converged else reason.lower(), residual=float(res),
                    measures=meas, history=conv.history, seconds=time.perf_counter() - t0,
                    snes_type=snes.getType(), ksp_type=snes.getKSP().getType(), edge_stalled=conv.edge_stalled,
                    **form.diagnostics(int(lits)))
        return state.g, state.p, act, info      # not copies: the state is dropped below
    finally:
        form.release()
        for obj in (X, Fv, J, snes):
            if obj is not None:
                obj.destroy()
        # Free the solve's N^2 arrays now.  The callbacks and their PETSc objects reference each other
        # (partly through C, invisible to the cyclic GC): drop the references and collect.  petsc4py
        # then only parks the collected objects of a multi-rank communicator (a collective destroy
        # from a finaliser could deadlock), and a parked PC keeps its Python context alive:
        # garbage_cleanup destroys them (+0.9 GB per case and rank at 4096^2 on 2 ranks without it).
        form = conv = state = snes = X = Fv = J = None
        gc.collect()
        PETSc.garbage_cleanup(comm)
        _remove_options(PETSc, keys)
