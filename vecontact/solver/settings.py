"""Every tuning constant of the exact solver: one frozen dataclass, one line a field.

Units: everything is nondimensional (gaps in h_rms, pressures in sigma0, see operator.py) or a count;
areas are fractions A/A0 of the grid; memories are bytes per rank.  The measurements behind the
defaults marked [RESULTS.md] are in benchmarks/RESULTS.md, one table per setting.

Overrides, the last one wins:

1. the defaults below;
2. ``solve_contact(..., settings=SolverSettings(restart_max=60))`` (library use);
3. the PETSc-style option ``-vc_<field> <value>`` (PREFIX = "vc_") in ``numerics.petsc`` or on the
   command line (``vecontact run job.yaml -vc_restart_max 60``), read by the one options parser
   (vecontact/solver/options.py) and checked when the job is loaded.  These options set fields only:
   they never reach PETSc's options database.

PETSc's own options keep their names and their usual effect (``-snes_*``, ``-ksp_*`` for the inner
solve of the free-set steps, ``-contact_ksp_*`` for that of the contact-set steps); the values vecontact
gives them unless the user does are the PETSC_* tables at the end.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

__all__ = ["SolverSettings", "PREFIX", "PETSC_DEFAULTS", "PETSC_VI_DEFAULTS", "PETSC_INNER_DEFAULTS",
           "PETSC_FREE_DEFAULTS", "PETSC_FREE_CYCLE_DEFAULTS", "PETSC_GLOBAL_DEFAULTS", "gmres_restart"]

PREFIX = "vc_"


def _knob(default, doc, lo=None, hi=None, lo_open=False, choices=None):
    """A field: its default, its one-line meaning and its allowed range [lo, hi] ((lo, hi] with lo_open)."""
    return field(default=default, metadata=dict(doc=doc, lo=lo, hi=hi, lo_open=lo_open, choices=choices))


@dataclass(frozen=True)
class SolverSettings:
    """Tuning constants of solve_contact (contact.py), the semismooth Newton solve (snes.py, policy.py,
    contactset.py, freeset.py), the warm starts (warmstart.py), Polonsky-Keer (pk.py) and operator.py."""

    # --- Newton iterations and the Krylov tolerances of their steps (policy.py)
    newton_max_it: int = _knob(100, "Newton iterations on the finest grid (numerics.max_iterations wins)", lo=1)
    fallback: str = _knob("vi", "a finest-grid solve whose full steps did not converge in newton_max_it starts "
                          "again from its first iterate with PETSc's reduced-space VI Newton and the bt line "
                          "search (vi), or with this PETSc line search on the full steps; a failed search still "
                          "takes its step (none: never) [RESULTS.md]", choices=("vi", "bt", "cp", "l2", "none"))
    vi_step_rtol: float = _knob(1e-5, "Krylov rtol of the VI method's steps, solved on its active set like a "
                                "contact-set step (vi.py) [RESULTS.md]", lo=0, hi=1, lo_open=True)
    vi_step_rtol_max: float = _knob(1e-2, "... with the bt line search, the iterate's measure within "
                                    "[vi_step_rtol, this] instead, but vi_step_rtol after a loose step bt cut "
                                    "(at most vi_step_rtol: never) [RESULTS.md]", lo=0, hi=1, lo_open=True)
    vi_stall: int = _knob(20, "... its attempt ends once its measure has not reached a new lowest in this many "
                          "Newton iterations: converging ones went at most 8, a failing one ran 300 (0: never) "
                          "[RESULTS.md]", lo=0)
    vi_capped_restart: int = _knob(400, "... the FGMRES restart of a VI step after one that used all of ksp_max_it short "
                                   "of its rtol (restarted FGMRES stagnates there; inner_restart_max otherwise; "
                                   "within the Krylov memory farm.memory counts, vi_restart; 0: never) "
                                   "[RESULTS.md]", lo=0)
    fallback_max_it: int = _knob(300, "Newton iterations of the fallback's attempt (numerics.max_iterations "
                                 "wins): bt's measure falls by a few % an iteration [RESULTS.md]", lo=1)
    fallback_coarse: str = _knob("on", "on: a coarse grid whose full steps end unconverged at coarse_max_it "
                                 "is solved again by the fallback (to coarse_max_it), and the finer grids, the "
                                 "finest too, start with the fallback's attempt [RESULTS.md]", choices=("on", "off"))
    fallback_coarse_measure: float = _knob(10.0, "... only if its measure ended above this (the study's coarse "
                                           "grids have ended unconverged at up to 0.17; below 10 the rule lost "
                                           "1.4-1.7x on some hard solves, from 38 up it gained 4-12x) [RESULTS.md]",
                                           lo=0)
    coarse_stall: int = _knob(5, "... or sooner, once its full steps' measure has not reached a new lowest in this "
                              "many Newton iterations while that lowest is above fallback_coarse_measure "
                              "(0: never) [RESULTS.md]", lo=0)
    coarse_stall_min_n: int = _knob(128, "... on coarse grids of at least this N [RESULTS.md]", lo=1)
    fallback_stall: int = _knob(10, "... or sooner, once its full steps' measure has not reached a new lowest in "
                                "this many Newton iterations (0: never; was 20 until the fallback was the VI "
                                "method) [RESULTS.md]", lo=0)
    cycle_rtol: float = _knob(1e-5, "... or at once, once its measure comes back to within this relative difference "
                              "of one 2 to cycle_period iterates before, the last one differing: full steps "
                              "that cycle never converge (0: never) [RESULTS.md]", lo=0, hi=1)
    cycle_period: int = _knob(4, "... the longest cycle looked for", lo=2)
    lin_rtol: float = _knob(0.1, "Krylov rtol of a Newton step whose active set changed", lo=0, hi=1, lo_open=True)
    lin_rtol_min: float = _knob(1e-6, "lin_rtol is never tightened below this", lo=0, hi=1, lo_open=True)
    first_rtol_factor: float = _knob(0.1, "first step of each grid level: rtol = this x lin_rtol [RESULTS.md]",
                                     lo=0, hi=1, lo_open=True)
    exact_rtol: float = _knob(1e-14, "rtol once the active set stopped changing (the atol decides)",
                              lo=0, hi=1, lo_open=True)
    lin_maxit_changing: int = _knob(40, "Krylov iteration cap of a step whose active set changed [RESULTS.md]",
                                    lo=1)
    lin_maxit_growth: float = _knob(1.4, "... times this per doubling of N above lin_maxit_n (the oracle solve's "
                                    "growth per doubling, #15) [RESULTS.md]", lo=1)
    lin_maxit_n: int = _knob(2048, "the largest N whose changing steps' cap is lin_maxit_changing itself (the grids "
                             "it was measured on) [RESULTS.md]", lo=1)
    ksp_max_it: int = _knob(400, "Krylov iteration cap of any Newton step (and of the VI steps)", lo=1)
    wander_ratio: float = _knob(0.3, "set changes shrinking < 1/this per step: tighten [RESULTS.md]",
                                lo=0, lo_open=True)
    tighten_factor: float = _knob(0.1, "tightening multiplies lin_rtol by this", lo=0, hi=1, lo_open=True)
    tighten_maxit_factor: int = _knob(2, "tightening multiplies lin_maxit_changing by this (up to ksp_max_it)",
                                      lo=1)
    atol_retry_factor: float = _knob(0.03, "atol x this when an exact step on an unchanged set did not converge",
                                     lo=0, hi=1, lo_open=True)
    inner_atol_factor: float = _knob(5.0, "contact-set steps: atol x this (a gap error on C) [RESULTS.md]",
                                     lo=0, lo_open=True)
    # --- where a Newton step is solved: on the contact set or on the free set
    contact_step: str = _knob("auto", "auto (by contact_step_area), contact or free (free-set steps)",
                              choices=("auto", "contact", "free"))
    contact_step_area: float = _knob(0.3, "auto: contact-set steps up to this A/A0 [RESULTS.md]", lo=0, hi=1)
    contact_step_area_large: float = _knob(0.2, "auto: the same where max|E|/min|E| > contact_step_modulus_large "
                                           "[RESULTS.md]", lo=0, hi=1)
    contact_step_modulus_large: float = _knob(300.0, "range of |E(q_x v)| over the grid above which "
                                              "contact_step_area_large applies [RESULTS.md]", lo=0)
    contact_step_area_small: float = _knob(0.6, "auto: the same on grids of N >= contact_step_min_n where "
                                           "max|E|/min|E| <= contact_step_modulus_max [RESULTS.md]", lo=0, hi=1)
    contact_step_modulus_max: float = _knob(60.0, "range of |E(q_x v)| over the grid up to which "
                                            "contact_step_area_small applies (below 1: never) [RESULTS.md]", lo=0)
    contact_step_min_n: int = _knob(1024, "... on grids of at least this size (below it a contact-set step's own "
                                    "work per iteration outweighs the FFT pairs it saves) [RESULTS.md]", lo=1)
    # --- GMRES restarts: the cap, unless the basis would exceed the memory budget
    restart_max: int = _knob(120, "GMRES restart of the free-set steps (-ksp_gmres_restart wins) [RESULTS.md]",
                             lo=1)
    restart_memory: float = _knob(3e9, "bytes per rank for the free-set steps' Krylov basis [RESULTS.md]",
                                  lo=0, lo_open=True)
    free_cycle: int = _knob(20, "long free-set solves: FGMRES over cycles of this many GMRES its (0: never) "
                            "[RESULTS.md]", lo=0)
    cycle_after_cap: int = _knob(80, "cycles start after a changing free-set step used a cap of >= this [RESULTS.md]",
                                 lo=1)
    cycle_after_cap_large: int = _knob(40, "the same where max|m_q|/min|m_q| > cycle_range_max [RESULTS.md]", lo=1)
    cycle_range_max: float = _knob(1.5e5, "stiffness range above which cycle_after_cap_large applies [RESULTS.md]",
                                   lo=0)
    cycle_max_it: int = _knob(800, "Krylov iteration cap of an exact free-set step in cycles [RESULTS.md]", lo=1)
    measure_stop: str = _knob("on", "on: an exact step stops once its update meets the SNES's test "
                              "(measurestop.py) [RESULTS.md]", choices=("on", "off"))
    changing_precision: str = _knob("single", "single: the steps whose active set changes solve with a float32 "
                                    "Krylov basis (single.py) [RESULTS.md]", choices=("single", "double"))
    single_rtol_min: float = _knob(1e-2, "... only while their rtol is at least this (tighter: the float32 "
                                   "basis falls short) [RESULTS.md]", lo=0, hi=1, lo_open=True)
    single_rtol_min_contact: float = _knob(0.0, "... the same on the contact set (flexible: the solution is "
                                           "formed from the preconditioned vectors) [RESULTS.md]", lo=0, hi=1)
    single_range_max: float = _knob(1.5e5, "... with float32 FFT pairs too while max|m_q|/min|m_q| <= this, else "
                                    "float64 pairs and a float32 basis [RESULTS.md]", lo=0)
    mixed_pairs: str = _knob("on", "on: where their pairs are float64, a float32-basis step's products take "
                             "the backward (A) or forward (B) transform in float32 (subset.Mixed) [RESULTS.md]",
                             choices=("on", "off"))
    mixed_reduction_max: float = _knob(1e5, "the steps PETSc solves (exact, tightened) form their operator with a "
                                       "float32 backward transform (subset.Mixed) while they must cut their "
                                       "residual by at most this (0: never) [RESULTS.md]", lo=0)
    single_exact_reduction_max: float = _knob(1e5, "exact steps (not in the free set's cycles) and, where float32 "
                                              "pairs hold, the VI method's solve with a float32 basis (single.py, "
                                              "flexible) while they must cut their residual by at most this (0: "
                                              "never) [RESULTS.md]", lo=0)
    single_stall_reduction: float = _knob(1e-4, "a float32-basis step's cycle (single.py) restarts from its float64 "
                                          "residual once its estimate is below this x the cycle's start and "
                                          "stalls (0: never) [RESULTS.md]", lo=0, hi=1)
    single_stall_window: int = _knob(10, "... stalls: fell by less than half over this many iterations", lo=1)
    cycle_precision: str = _knob("single", "single: the GMRES cycles of long free-set solves (free_cycle) with a float32 "
                                 "basis under PETSc's float64 FGMRES (subset.SingleCycles) [RESULTS.md]",
                                 choices=("single", "double"))
    pc_range_max: float = _knob(1e6, "the preconditioners of FGMRES (free-set cycles, contact-set stiffness) with "
                                "float32 FFT pairs while max|m_q|/min|m_q| <= this (0: never) [RESULTS.md]", lo=0)
    edge_window: int = _knob(2, "contact-set steps: half width of the windows of the preconditioner's edge "
                             "correction (edge.py; 0: none) [RESULTS.md]", lo=0, hi=3)
    edge_drop: float = _knob(0.2, "... its entries below this fraction of their row's largest are dropped [RESULTS.md]",
                             lo=0, hi=1)
    edge_window_large: int = _knob(1, "... the half width instead on contact sets of at least edge_large_area of the "
                                   "grid where the modulus's range is at most edge_large_modulus_max (0: none) "
                                   "[RESULTS.md]", lo=0, hi=3)
    edge_large_area: float = _knob(0.2, "... that fraction of the grid's points (above 1: never)", lo=0)
    edge_large_modulus_max: float = _knob(60.0, "... that range of |E(q_x v)| over the grid", lo=0)
    edge_window_high: int = _knob(3, "... the half width instead on grids whose stiffness's range max|m_q|/min|m_q| "
                                  "is at least edge_high_range_min (fast sliding on fine grids; edge_window's "
                                  "value turns it off) [RESULTS.md]", lo=0, hi=3)
    edge_high_range_min: float = _knob(1.5e5, "... that range (2048^2 at 10 m/s, 4096^2 at 1 and 10 m/s for the "
                                       "paper's compound)", lo=0)
    edge_high_min_n: int = _knob(2048, "... on grids of at least this N (on 1024^2 they gained at most 0.91x "
                                 "and stalled a broad rubber: 3-21x) [RESULTS.md]", lo=1)
    edge_newton_max: int = _knob(25, "... the finest grid's solve not converged after this many Newton iterations "
                                 "with the term starts again without it (it can stall the steps; m_CC alone "
                                 "cannot; 0: never) [RESULTS.md]", lo=0)
    edge_stall: int = _knob(20, "... or sooner, once its measure has not reached a new lowest in this many "
                            "Newton iterations with the term in use (only where fallback_stall counts; 0: never) "
                            "[RESULTS.md]", lo=0)
    edge_capped_max: int = _knob(3, "... or sooner, once this many Newton steps in a row ran with the term and used "
                                 "the whole ksp_max_it (the stall's mark; any grid; 0: never) [RESULTS.md]", lo=0)
    edge_schur_modulus_min: float = _knob(300.0, "... where the modulus's range max|E|/min|E| over the grid exceeds "
                                          "this, the rows come from the stiffness on the window (\"schur\", edge.py) "
                                          "instead of the compliance's local inverses, and the half width is "
                                          "edge_window's (0: everywhere) [RESULTS.md]", lo=0)
    carry_directions: int = _knob(30, "a contact-set step's Krylov solve starts from this many of the last "
                                  "step's directions (carry.py, recycle.py; 0: none) [RESULTS.md]", lo=0)
    carry_memory: float = _knob(3e8, "... within this many bytes per rank", lo=0)
    carry_area_max: float = _knob(0.3, "... only while the contact set has at most this fraction of the grid "
                                  "(larger: the passes over its K vectors cost more than they save) [RESULTS.md]",
                                  lo=0, hi=1)
    carry_modulus_min: float = _knob(100.0, "... only where the modulus's range max|E|/min|E| over the grid's q_x is "
                                     "at least this (fast sliding: long steps; below it the passes cost more "
                                     "than they save) [RESULTS.md]", lo=0)
    carry_map_cost: float = _knob(10.0, "a changing contact-set step starts from the last step's K directions, "
                                  "mapped to its set (recycle.py), when |C| x (points changed + 2 K) <= this x N^2 "
                                  "(about that many FFT pairs; 0: never) [RESULTS.md]", lo=0)
    carry_drop: float = _knob(1e-8, "carried directions whose products' Gram eigenvalue is below this fraction of "
                              "the largest are left out (recycle.py)", lo=0, hi=1)
    inner_restart_max: int = _knob(100, "FGMRES restart of the contact-set steps' inner solve", lo=1)
    inner_restart_memory: float = _knob(3e9, "bytes per rank for the inner FGMRES basis [RESULTS.md]", lo=0,
                                        lo_open=True)
    restart_min: int = _knob(10, "no restart below this, whatever the memory", lo=1)
    store_headroom: float = _knob(0.05, "kept work arrays (float32-basis stores, the edge term's vectors) are made "
                                  "this much longer than asked, unwritten [RESULTS.md]", lo=0)
    # --- coarse grids and warm starts (contact.py, warmstart.py)
    coarse_min_n: int = _knob(64, "coarsest grid size (N/2, N/4, ... down to this) [RESULTS.md]", lo=2)
    coarse_levels: int = _knob(6, "coarse grids at most (6: down to coarse_min_n up to 4096^2) [RESULTS.md]", lo=0)
    coarse_tol: float = _knob(0.3, "convergence tolerance on the coarse grids (the fine one's if larger) [RESULTS.md]",
                              lo=0, hi=1, lo_open=True)
    coarse_max_it: int = _knob(50, "Newton iterations per coarse grid", lo=1)
    smooth_sweeps: int = _knob(6, "projected Richardson sweeps after each prolongation (warmstart.smooth_gap) "
                               "[RESULTS.md]", lo=0)
    smooth_ratio: float = _knob(6.0, "... their steps: Chebyshev nodes of [max|m_q| / this, max|m_q|] [RESULTS.md]",
                                lo=1)
    step_sweeps: int = _knob(4, "the same sweeps on the iterate after each Newton step on the finest grid solved on "
                             "the free set while its active set changes (snes.py; 0: none) [RESULTS.md]", lo=0)
    step_return_rtol: float = _knob(1e-6, "... and none once the measure comes back to the one two iterates before "
                                    "within this relative difference: the smoothed steps flip the same points to "
                                    "and fro (policy.py; 0: never) [RESULTS.md]", lo=0)
    bearing_area_min: float = _knob(1e-4, "cold start: Persson's A/A0 estimate clipped to at least this",
                                    lo=0, hi=1, lo_open=True)
    bearing_area_max: float = _knob(0.9, "... and to at most this", lo=0, hi=1, lo_open=True)
    bearing_tol: float = _knob(1e-9, "cold start: bisection tolerance of the flat's height (h_rms)",
                               lo=0, lo_open=True)
    # --- the other methods
    pk_max_it: int = _knob(20000, "Polonsky-Keer CG iterations (numerics.max_iterations wins)", lo=1)
    elastic_rtol: float = _knob(1e-12, "method pk: |Im E| <= this |E| on every q_x counts as elastic", lo=0)
    # --- the process while it solves (contact.py)
    huge_pages: str = _knob("off", "off: numpy does not ask for huge pages (madvise) for the arrays a solve "
                            "allocates; on: numpy's own choice [RESULTS.md]", choices=("off", "on"))

    def __post_init__(self):
        for f in fields(self):
            _check(f, getattr(self, f.name))
        if self.bearing_area_min > self.bearing_area_max:
            raise ValueError(f"bearing_area_min {self.bearing_area_min} > bearing_area_max {self.bearing_area_max}")

    # ------------------------------------------------------------------ derived values
    def step_area(self, modulus_range, n):
        """A/A0 up to which ``contact_step auto`` solves Newton steps on the contact set of an n x n grid
        whose modulus has the range max|E|/min|E| over the grid's q_x (ContactOperator.modulus_range; it
        grows with the speed, and with N only as the rubber's frequencies do): at a high modulus range
        the contact set wanders between the steps solved on it, whatever the grid (the stiffness's
        range, which also holds the grid's q range, did not place the switch on both 2048^2 and
        4096^2); at a low modulus range on large grids the contact-set steps take fewer FFT pairs than
        the free set's at any area, and their own work per iteration (edge correction, halos) weighs
        little beside a pair."""
        if modulus_range > self.contact_step_modulus_large:
            return self.contact_step_area_large
        if modulus_range <= self.contact_step_modulus_max and n >= self.contact_step_min_n:
            return self.contact_step_area_small
        return self.contact_step_area

    def edge_half_width(self, modulus_range, area, stiffness_range=0.0, n=0):
        """The half width of the edge correction's windows (edge.py; 0: none) for a contact set holding
        the fraction ``area`` of the points of an ``n`` x ``n`` grid, whose modulus has the range
        max|E|/min|E| over its q_x and whose stiffness has the range ``stiffness_range`` max|m_q|/min|m_q|:
        edge_window_large on large sets at a low modulus range (slow sliding), where the edges are many
        and the set moves little between steps, so that the narrower windows' cheaper products and builds
        outweigh their extra iterations; edge_window where the rows are the Schur ones (``edge_rows``),
        whose wider windows gain nothing; else edge_window_high from a stiffness range of
        edge_high_range_min (fast sliding on fine grids) on grids from edge_high_min_n up, where the
        wider windows' fewer iterations outweigh their builds; edge_window elsewhere, and nowhere when
        it is 0."""
        if self.edge_window == 0:
            return 0
        if area >= self.edge_large_area and modulus_range <= self.edge_large_modulus_max:
            return self.edge_window_large
        if self.edge_rows(modulus_range) == "schur":
            return self.edge_window
        if stiffness_range >= self.edge_high_range_min and n >= self.edge_high_min_n:
            return self.edge_window_high
        return self.edge_window

    def edge_rows(self, modulus_range):
        """The kind of the edge correction's rows (edge.EdgeCorrection ``rows``) on a grid whose modulus has
        the range max|E|/min|E| over its q_x: the compliance's local inverses ("inverse"), which cut the
        most iterations, up to edge_schur_modulus_min; above it the stiffness's Schur complement on the
        window ("schur"), as the local inverses there can make the preconditioner indefinite and the
        steps stall."""
        return "schur" if modulus_range > self.edge_schur_modulus_min else "inverse"

    def widest_step_area(self, n):
        """The largest A/A0 step_area gives an n x n grid at any modulus range (the contact
        set a contact-set step may be solved on, whatever the speed: farm.memory): the range at each
        of its bounds and beyond, never below 1 (max|E|/min|E| is at least 1)."""
        return max(self.step_area(e, n) for e in (1.0, self.contact_step_modulus_max,
                                                   self.contact_step_modulus_large, math.inf) if e >= 1.0)

    def stall(self):
        """SingleGMRES.solve's ``stall`` of the float32-basis steps: (single_stall_reduction,
        single_stall_window), or None where single_stall_reduction is 0."""
        if self.single_stall_reduction == 0:
            return None
        return self.single_stall_reduction, self.single_stall_window

    def step_precision(self, reduction, float32_basis=True):
        """(single, mixed) of a step that must cut its residual by ``reduction`` (an exact step's, or a VI
        step's 1 / rtol): a float32 basis (single.py, flexible) while ``float32_basis`` and ``reduction``
        <= single_exact_reduction_max; else, in PETSc, its operator with mixed pairs while ``reduction``
        <= mixed_reduction_max: float32 rounding holds such solves near 1e-7 of their start."""
        single = float32_basis and 0 < self.single_exact_reduction_max and reduction <= self.single_exact_reduction_max
        return single, not single and reduction <= self.mixed_reduction_max

    def vi_rtol(self, measure):
        """Krylov rtol of a VI step from an iterate whose convergence measure (operator.py) is ``measure``:
        the measure itself within [vi_step_rtol, vi_step_rtol_max], so the steps tighten as the
        iterates converge (forcing proportional to the residual keeps Newton's quadratic end)."""
        return max(self.vi_step_rtol, min(self.vi_step_rtol_max, float(measure)))

    def maxit_changing(self, n):
        """Krylov iteration cap of a changing Newton step on an n x n grid: lin_maxit_changing up to
        lin_maxit_n, then x lin_maxit_growth per doubling.  The Krylov iterations a step needs grow
        with N (x1.4 per doubling for the oracle solve), so a cap measured on the smaller grids stops
        the finer grids' first steps short of their rtol, and the set they start from then wanders
        [RESULTS.md]."""
        if n <= self.lin_maxit_n:
            return self.lin_maxit_changing
        return int(round(self.lin_maxit_changing * self.lin_maxit_growth ** math.log2(n / self.lin_maxit_n)))

    def cycle_cap(self, stiffness_range):
        """The smallest iteration cap whose exhaustion by a changing free-set step starts the cycles
        (StepPolicy.record_iterations) on a grid whose stiffness has the range max|m_q|/min|m_q|: the
        first cap at high range (fast sliding, large N), where the steps' Krylov solves are long from
        the start; a tightened one elsewhere, where the cycles' extra iterations lose."""
        if stiffness_range > self.cycle_range_max:
            return self.cycle_after_cap_large
        return self.cycle_after_cap

    def restart(self, n_local, vectors=1, reserve=0):
        """GMRES restart of the free-set steps (n_local: local free points; GMRES: 1 basis vector an
        iteration, FGMRES and the VI method's whole-grid FGMRES: 2; ``reserve``: vectors of the budget
        held elsewhere, the inner GMRES of free_cycle)."""
        return gmres_restart(n_local, self.restart_memory - 8.0 * reserve * n_local, vectors, self.restart_max,
                             self.restart_min)

    def single_restart(self, n_local, mode, vectors, reserve=0):
        """Restart of a single-precision step solve (single.py) on the free set (mode "free": as
        ``restart``) or the contact set ("contact": the inner_ budget); ``vectors``: float64 vectors'
        worth of memory an iteration (0.5 for a float32 basis vector); ``reserve``: float32 vectors of
        the budget held elsewhere (the inner GMRES of cycles)."""
        if mode == "contact":
            return gmres_restart(n_local, self.inner_restart_memory, vectors, self.inner_restart_max,
                                 self.restart_min)
        return self.restart(n_local, vectors, reserve / 2)

    def krylov_bytes(self, N, n_local):
        """Bytes of a rank's largest Krylov basis by the restart rules on an N x N grid, ``n_local`` its
        points (farm.memory counts it): the free-set GMRES over all of them, or the contact-set steps'
        inner FGMRES (two vectors an iteration) over the widest set they solve on (widest_step_area;
        all points with contact_step "contact")."""
        n = float(n_local)
        n_contact = {"contact": 1.0, "free": 0.0}.get(self.contact_step, self.widest_step_area(N)) * n
        return 8.0 * max((self.restart(n) + 1) * n, 2 * (self.inner_restart(n_contact) + 1) * n_contact)

    def vi_restart(self, N, n_local, n_active):
        """FGMRES restart of a VI step after one that ran out of ksp_max_it (vi.py), on ``n_active`` of a
        rank's ``n_local`` points of an N x N grid: vi_capped_restart within inner_restart_memory and
        krylov_bytes(N, n_local), so that the farm's memory estimate holds, and never below
        inner_restart(n_active); that where vi_capped_restart is 0."""
        budget = min(self.inner_restart_memory, self.krylov_bytes(N, n_local))
        longer = gmres_restart(n_active, budget, 2, self.vi_capped_restart, self.restart_min)
        return max(self.inner_restart(n_active), longer if self.vi_capped_restart else 0)

    def inner_restart(self, n_local):
        """FGMRES restart of the inner solve of the contact-set steps (n_local: local contact points)."""
        return gmres_restart(n_local, self.inner_restart_memory, 2, self.inner_restart_max, self.restart_min)

    # ------------------------------------------------------------------ options
    def with_options(self, options):
        """A copy with the ``-vc_<field>`` entries of ``options`` (a parsed options dict, see
        options.parse) applied; other entries are ignored.  ValueError names a bad one."""
        known = {f.name: f for f in fields(self)}
        changes = {}
        for key, text in options.items():
            if not key.startswith(PREFIX):
                continue
            name = key[len(PREFIX):]
            if name not in known:
                raise ValueError(f"-{key}: unknown solver setting (known: {', '.join(sorted(known))})")
            changes[name] = _convert(known[name], key, text)
        try:
            return replace(self, **changes)
        except ValueError as exc:
            raise ValueError(f"-{PREFIX}{exc}") from None


def gmres_restart(n_local, memory, vectors, cap, minimum):
    """Restart length: ``cap``, reduced so that ``vectors`` x (restart + 1) basis vectors of ``n_local``
    doubles fit in ``memory`` bytes, never below ``minimum`` (4096^2 on 2 ranks, 3 GB: GMRES 43, FGMRES 21)."""
    return int(max(minimum, min(cap, memory // (8 * vectors * max(n_local, 1)) - 1)))


def _convert(f, key, text):
    """The option's text as the field's type (bool is no field type)."""
    if text is None:
        raise ValueError(f"-{key}: needs a value")
    kind = type(f.default)
    try:
        return kind(text)
    except ValueError:
        raise ValueError(f"-{key}: expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None


def _check(f, value):
    m = f.metadata
    if m["choices"] is not None:
        if value not in m["choices"]:
            raise ValueError(f"{f.name}: expected one of {', '.join(m['choices'])}, got {value!r}")
        return
    kind = type(f.default)
    if isinstance(value, bool) or not isinstance(value, kind if kind is int else (int, float)) \
            or not math.isfinite(value):
        raise ValueError(f"{f.name}: expected {'an integer' if kind is int else 'a finite number'}, got {value!r}")
    lo, hi = m["lo"], m["hi"]
    if (lo is not None and (value <= lo if m["lo_open"] else value < lo)) or (hi is not None and value > hi):
        rng = f"{'(' if m['lo_open'] else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        raise ValueError(f"{f.name}: {value!r} is outside {rng}")


# ---------------------------------------------------------------------------------------------------
# Values vecontact gives PETSc's own options unless the user gives them ([RESULTS.md]: measured there).

# SNES of the semismooth Newton method (solver prefix) [RESULTS.md]
PETSC_DEFAULTS = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "basic",          # full Newton steps (primal-dual active set)
    "snes_max_linear_solve_fail": "1000",     # a step capped by its iteration limit is still used
}
# -snes_type vinewtonrsls (vi.py): the reduced-space VI Newton method [RESULTS.md]
PETSC_VI_DEFAULTS = {
    "ksp_type": "preonly",                    # the PC solves the step (vi.py, ViNewton.iterate)
    "snes_vi_zero_tolerance": "1e-12",        # absolute, hence nondimensional unknowns (docs/conventions.md §7)
    "snes_linesearch_type": "basic",
}
# ksp_min_it 1 in both inner KSPs: a step whose first residual already met its atol would otherwise
# return a zero update, i.e. a whole Newton step that leaves the iterate short of tol [RESULTS.md]
# inner KSP of the contact-set steps (prefix <solver>contact_); ksp_gmres_restart from inner_restart()
PETSC_INNER_DEFAULTS = {"ksp_type": "fgmres", "ksp_min_it": "1"}
# inner KSP of the free-set steps (the solver prefix itself, freeset.py): the PC is a fixed linear map,
# so right-preconditioned GMRES does what FGMRES does with half the basis; ksp_gmres_restart from
# restart() of the free set's size [RESULTS.md]
PETSC_FREE_DEFAULTS = {"ksp_type": "gmres", "ksp_pc_side": "right", "ksp_min_it": "1"}
# the same with free_cycle k > 0 and cycle_precision double: FGMRES whose PC (PCKSP, inner prefix
# <solver>ksp_) runs exactly k unpreconditioned GMRES iterations (pc_type none: explicit, as PETSc
# remade the inner KSP with it whenever the free set changed size); the outer basis is short, so the
# orthogonalisation is cheap [RESULTS.md]; ksp_gmres_restart from restart(), ksp_ksp_max_it and
# ksp_ksp_gmres_restart = k
PETSC_FREE_CYCLE_DEFAULTS = dict(PETSC_FREE_DEFAULTS, ksp_type="fgmres", pc_type="ksp", ksp_ksp_type="gmres",
                                 ksp_ksp_pc_side="right", ksp_ksp_rtol="1e-30", ksp_ksp_atol="0",
                                 ksp_ksp_min_it="0", ksp_ksp_pc_type="none")
# global (unprefixed): PETSc's own VecMDot/VecMAXPY kernels, not the reference BLAS's dgemv [RESULTS.md]
PETSC_GLOBAL_DEFAULTS = {"vec_mdot_use_gemv": "0", "vec_maxpy_use_gemv": "0"}
