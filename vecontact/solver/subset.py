"""What the two Newton-step solvers share: an inner Krylov solve whose vectors live on a subset S of
the grid (the contact set C in contactset.py, the free set F in freeset.py).

Both are PETSc Python PCs of the outer (Newton) KSP, which is ``preonly``: the PC solves the Newton
system J x = r (snes.py) by eliminating the complement of S exactly and running an inner KSP on S.
Orthogonalisation, the memory-bound part of a Krylov iteration, then costs |S| instead of N^2 per
basis vector, and the GMRES restart that fits the memory budget grows by N^2 / |S|.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np
from mpi4py import MPI

from vecontact.solver.carry import CarriedDirections
from vecontact.solver.recycle import CarriedSpace
from vecontact.solver.single import SingleGMRES

__all__ = ["Grid", "Mixed", "Restricted", "SingleCycles", "SubsetStep", "Workspace", "counters", "gather"]


def gather(full, idx, out):
    """``out`` = the entries ``idx`` (flat, in range) of the local rows ``full``; returns ``out``.  Not
    take's default mode="raise": it buffers ``out``, 1.3-2.9x slower (RESULTS.md)."""
    return np.take(full.ravel(), idx, out=out, mode="wrap")


class Grid:
    """Where a Restricted product (and vi.py's sub-matrix product) is formed: a SlabFFT (a step's, or
    its single-precision twin), its real buffer ``buf`` (zero outside the points of the last
    ``scatter``), the whole-grid product ``out``, a scratch of their dtype (``gathered``) for products
    wanted in the other precision, and the multipliers cast to its precision (``cast``, one copy each)."""

    def __init__(self, fft):
        self.fft = fft
        self.buf = fft.real_array()
        self.out = fft.real_array()
        self.support = np.zeros(0, dtype=np.intp)     # the points the last scatter wrote
        self._gathered = np.empty(0, dtype=self.buf.dtype)
        self._casts = {}

    def scatter(self, idx, x, norm=None):
        """``buf`` = x on the flat local points ``idx`` and zero elsewhere: the previous scatter's
        points are cleared when ``idx`` is another array (a new S, or the other step type's).  With
        ``norm``, x times that number (through the ``gathered`` scratch)."""
        flat = self.buf.reshape(-1)
        if self.support is not idx:
            flat[self.support] = 0.0
            self.support = idx
        if norm is not None:
            x = np.multiply(x, norm, out=self.gathered(idx.size), casting="same_kind")
        flat[idx] = x       # not .flat[idx] nor np.put: slower (RESULTS.md)

    def load(self, idx, x, scale):
        """Scatter x as the input of a product with ``scale``; True when it carries the 1/N^2 (scale 1:
        taken on the |S| entries of x instead of in a pass over the N^2 of the output, SlabFFT.apply's
        normalised; for N a power of two 1/N^2 is one, so the same bits)."""
        unscaled = scale == 1.0
        self.scatter(idx, x, self.fft.norm if unscaled else None)
        return unscaled

    def product_of(self, idx, x, multiplier, scale):
        """``out`` = scale x (multiplier applied to x on the points ``idx``, zero elsewhere)."""
        self.fft.apply(self.buf, multiplier, self.out, scale, normalised=self.load(idx, x, scale))

    def cast(self, multiplier):
        """``multiplier`` in the grid's precision (the same array if it already is; made once)."""
        m = np.asarray(multiplier)
        dtype = self.fft.complex_dtype if np.iscomplexobj(m) else self.fft.real_dtype
        if m.dtype == dtype:
            return m
        hit = self._casts.get(id(multiplier))
        if hit is None or hit[0] is not multiplier:      # the source is kept, so its id stays its own
            hit = self._casts[id(multiplier)] = (multiplier, m.astype(dtype))
        return hit[1]

    def gathered(self, n):
        """A scratch array of n entries, of the grid's dtype."""
        if self._gathered.size < n:
            self._gathered = np.empty(n, dtype=self.buf.dtype)
        return self._gathered[:n]


class Mixed:
    """A Grid whose products take their forward transform on ``src`` and their backward on ``dst`` (the
    float64 Grid and the float32 one, either way round; SlabFFT.apply_across): scatter into src's
    ``buf``, product into dst's ``out``, both Grids' buffers shared (no memory of its own).  The
    multiplier stays float64 (``cast`` is the identity): the product is rounded to float32 only where
    the float32 side is (SolverSettings.mixed_pairs).  ``step.mixed_pairs`` counts its products."""

    def __init__(self, src, dst, step):
        self.src, self.dst, self.step = src, dst, step

    @property
    def buf(self):
        return self.src.buf

    @property
    def out(self):
        return self.dst.out

    def cast(self, multiplier):
        return multiplier

    def gathered(self, n):
        return self.dst.gathered(n)

    def product_of(self, idx, x, multiplier, scale):
        normalised = self.src.load(idx, x, scale)
        self.src.fft.apply_across(self.dst.fft, self.src.buf, multiplier, self.dst.out, scale, normalised=normalised)
        self.step.mixed_pairs += 1


class Restricted:
    """y = (scale multiplier P_S x)_S, then ``post(y, full)`` with ``full`` the whole-grid product (Python
    Mat and Python PC of the inner KSP).  ``multiplier``: a Fourier multiplier of the SlabFFT; ``scale``:
    a number (SlabFFT.apply: no scaled copy of the multiplier).  ``grid``: the Grid where the product is
    formed (default the step's float64 one).  ``local``: a term added to y before ``post``, local(x, y)
    adds it (contactset.py's edge correction, EdgeCorrection.add_to)."""

    def __init__(self, step, multiplier, post=None, grid=None, scale=1.0, local=None):
        self.step = step
        self.multiplier = multiplier
        self.post = post
        self.grid = step.grid if grid is None else grid
        self.scale = float(scale)
        self.local = local

    def on(self, grid):
        """The same product formed on ``grid`` (the multiplier cast to its precision)."""
        if grid is self.grid:
            return self
        return Restricted(self.step, grid.cast(self.multiplier), self.post, grid, self.scale, self.local)

    def matvec(self, x, y):
        """y = the product of x (arrays of the local points of S; y of another precision than the
        grid's goes through ``grid.gathered``)."""
        g = self.grid
        idx = self.step.idx
        g.product_of(idx, x, self.multiplier, self.scale)
        if y.dtype == g.out.dtype:
            gather(g.out, idx, y)
        else:                           # take's own casting copies (and casts) y's old contents first
            np.copyto(y, gather(g.out, idx, g.gathered(idx.size)), casting="same_kind")
        if self.local is not None:
            self.local(x, y)
        if self.post is not None:
            self.post(y, g.out)

    def _apply(self, x, y):
        self.matvec(x.getArray(readonly=True), y.getArray())

    def mult(self, mat, x, y):
        carried = self.step.carried            # an exact step's first products: from memory (carry.py)
        if carried is None or not carried.serve_product(y.getArray()):
            self._apply(x, y)

    def apply(self, pc, x, y):
        carried = self.step.carried            # ... its first preconditioned vectors: the carried ones
        if carried is None:
            self._apply(x, y)
        elif not carried.serve_direction(y.getArray()):
            self.matvec(carried.next_input(x.getArray(readonly=True)), y.getArray())

    def setUp(self, pc):
        pass


class _Single:
    """What a step's inner solve in single precision (single.py) works with: its operator, on the
    step's float32 Grid when ``float32_pairs`` (work dtype float32) and else on its float64 one; its
    preconditioner, on the float32 Grid with ``float32_pc`` too; and the memory of the GMRES bases
    (kept between steps, viewed at the size of the current S)."""

    def __init__(self, step, float32_pairs, float32_pc=False):
        self.step = step
        grid = step.float32_grid() if float32_pairs else step.grid
        self.work = grid.buf.dtype.type
        self._B_grid = step.float32_grid() if float32_pairs or float32_pc else grid
        if not float32_pairs and step.settings.mixed_pairs == "on":
            # float64 pairs only where a float32 rounding would be amplified: A's input (z, a gap on
            # the free set) and B's output (its z); A's output goes into the float32 basis anyway
            grid = step.operator_mixed()
            if self._B_grid is step.grid:
                self._B_grid = Mixed(grid.dst, step.grid, step)
        self.A = step.operator().on(grid)
        self._stores = {}

    @cached_property
    def B(self):
        """The preconditioner (made on first use: the cycles never use it)."""
        return self.step.preconditioner().on(self._B_grid)

    def free(self):
        """Drop the bases' memory (made again by the next single-precision solve)."""
        self._stores = {}

    def gmres(self, slot, n_loc, restart, allsum, flexible, capacity=None):
        """A SingleGMRES working in the memory of ``slot``.  A store too small for it is made again, for
        the restart ``capacity`` (default ``restart``; one the memory budget allows) on n_loc and
        SolverSettings.store_headroom more points: a store's pages fault in on first write, and a new
        store makes every row fault again, where the steps of one grid ask for a few more points or a
        longer restart each [RESULTS.md].  Pages never written cost no memory; only the store that is
        too small (basis or work) is made again."""
        need = SingleGMRES.sizes(n_loc, restart, flexible)
        stores = list(self._stores.pop(slot, None) or (None, None))      # so that a block too small can go
        if any(a is None or a.size < n for a, n in zip(stores, need)):
            room = int(n_loc * (1.0 + self.step.settings.store_headroom)) + 1
            size = SingleGMRES.sizes(room, max(restart, capacity or 0), flexible)
            for i, dtype in enumerate((np.float32, self.work)):
                if stores[i] is None or stores[i].size < need[i]:
                    stores[i] = None            # free the old block first
                    stores[i] = np.empty(size[i], dtype=dtype)
        self._stores[slot] = tuple(stores)
        return SingleGMRES(n_loc, restart, allsum, flexible, self.work, stores[0][:need[0]], stores[1][:need[1]])


class SingleCycles:
    """Python PC of a step's inner FGMRES (PETSc, float64 basis): exactly ``cycle`` iterations of
    unpreconditioned GMRES on the step's operator, with a float32 basis (single.py; its pairs in
    float32 by SubsetStep.cycle_context).  A cycle cuts the residual by far less than float32
    rounding limits, and the outer FGMRES keeps its own float64 space across the cycles (its operator
    in float64), so steps solved to any tolerance (exact ones too, with the measure stop on the outer
    KSP) keep a float32 basis where the work is (SolverSettings.cycle_precision).  Unpreconditioned,
    as PETSc's cycles (settings.PETSC_FREE_CYCLE_DEFAULTS): with the step's compliance PC the solves
    took 1.2-1.7x the pairs [RESULTS.md]."""

    def __init__(self, step, cycle):
        self.step = step
        self.cycle = int(cycle)

    def setUp(self, pc):
        pass

    def run(self, v, out):
        """One cycle: ``out`` (float64 or the work dtype) from ``v``; returns its iterations."""
        step = self.step
        sg = step.cycle_context()
        gm = sg.gmres("inner", int(step.idx.size), self.cycle, step.fft._allsum, flexible=False)
        return gm.solve(sg.A.matvec, None, v, out, 0.0, 0.0, self.cycle)[0]

    def apply(self, pc, x, y):
        self.step.single_iterations += self.run(x.getArray(readonly=True), y.getArray())


class Workspace:
    """The whole-grid arrays of the Newton steps, held once for both step types (a solve runs one step
    at a time): the float64 Grid, the float32 one (made on first use), and two real scratch arrays,
    ``w`` (a step's right-hand side work) and ``s`` (ContactSetStep.update's; made on first use)."""

    def __init__(self, fft):
        self.fft = fft
        self.grid = Grid(fft)
        self.w = fft.real_array()
        self._grid32 = None
        self._s = None

    def float32_grid(self):
        """The Grid on the SlabFFT's single-precision twin (made on first use)."""
        if self._grid32 is None:
            self._grid32 = Grid(self.fft.single())
        return self._grid32

    @property
    def s(self):
        if self._s is None:
            self._s = self.fft.real_array()
        return self._s


def counters(steps):
    """The precision and carry counts of the inner solves of ``steps`` (SubsetSteps), for a solve's
    diagnostics."""
    steps = list(steps)
    return dict(single_iterations=sum(s.single_iterations for s in steps),
                float32_pairs=any(s.ran_float32_pairs for s in steps),
                mixed_pairs=sum(s.mixed_pairs for s in steps),
                carried_directions=sum(s.carried_directions for s in steps),
                stalls=sum(s.stalls for s in steps))


class SubsetStep:
    """Base of the Newton-step PCs: the inner KSP on the points ``idx`` of S, its restricted operator,
    the option defaults it puts into PETSc's database (removed again by ``release``) and the count of
    its iterations.

    A subclass gives ``defaults(n_loc)`` (option defaults under ``inner_prefix``, from the local size
    of the first S), ``operator()`` and ``preconditioner()`` (Restricted contexts) and ``apply``; it
    calls ``select(idx, n_S)`` from its ``set_active`` and ``solve()`` from its ``apply``.
    ``work``: the Workspace it shares with the other step type (default: its own).
    """

    def __init__(self, op, kappa, PETSc, inner_prefix, settings, work=None):
        self.op = op
        self.fft = fft = op.fft
        self.comm = fft.comm
        self.kappa = float(kappa)
        self.PETSc = PETSc
        self.settings = settings
        self.shape = fft.local_real_shape
        self.work = Workspace(fft) if work is None else work
        self.grid = self.work.grid      # the float64 products (Restricted)
        self.out = self.grid.out
        self.w = self.work.w
        self._ran32 = False             # this step made products on the float32 Grid
        self.idx = np.zeros(0, dtype=np.intp)
        self._r = None                  # right-hand side (local rows) of the running apply, for update()
        self.n_S = 0
        self.single = False             # the next solves in single precision (set_tolerances)
        self._single = None             # _Single, made on the first single-precision solve
        self.float32_pairs = None       # its pairs in float32 too (the stiffness's range, _Single)
        self._cycles = None             # _Single of the float32 cycles (cycle_context)
        self.iterations = 0             # inner Krylov iterations of the ``solves`` applies
        self.single_iterations = 0      # ... of them with a float32 basis (single.py)
        self.mixed_pairs = 0            # pairs with one transform in float32 (Mixed)
        self.carried_directions = 0     # directions exact solves started from (carry.py), no pair each
        self.stalls = 0                 # float32-basis cycles restarted on a stalled estimate (single.py)
        self.cycle = 1                  # Krylov iterations per iteration of self.ksp (nested: the inner's)
        self.solves = 0
        self.forcing = False            # -snes_ksp_ew: each solve takes the rtol PETSc's Eisenstat-Walker
        self._outer = None              # forcing gave the outer KSP (activate's), which preonly ignores
        self._A = self._b = self._y = self._A_ctx = None
        self.mixed = False              # the next PETSc solve's operator with mixed pairs (set_tolerances)
        self._mixed_grid = None         # the operator's Mixed (operator_mixed)
        self.ksp = PETSc.KSP().create(comm=self.comm)
        self._prefix = inner_prefix
        self.ksp.setOptionsPrefix(inner_prefix)
        self._configured = False
        self._own_keys = []
        self._carry_from = None         # the last single-precision FGMRES solve and what it carried (_last_space)
        self._unchanged = False         # the next solve's set is the last solve's (carry)
        self.removed = 0.0              # the mean the operator's P took off its last product (ContactSetStep)
        self.carried = None             # the directions the running PETSc solve starts from (carry.py)
        self.flexible = False           # the next float32-basis solve keeps its preconditioned vectors (set_tolerances)
        self.stop = None                # the MeasureStop attached to this step, if any (measurestop.py)

    def activate(self, ksp):
        """Solve the next Newton steps with the outer ``ksp`` as preonly + this PC."""
        self._carry_from = None         # the last solve of this step type was not the last Newton step's
        ksp.setType("preonly")
        self._outer = ksp
        ksp.getPC().setType("python")     # a -pc_type under the shared prefix is the inner KSP's, not this one's
        ksp.getPC().setPythonContext(self)

    def set_tolerances(self, rtol, atol, max_it, single=False, mixed=False, flexible=False):
        """``max_it`` counts Krylov iterations; nested (``cycle`` > 1), whole cycles of the outer KSP.
        ``single``: solve in single precision (single.py) with these tolerances instead of the KSP;
        ``mixed``: else the KSP's operator with mixed pairs (_krylov_grid); ``flexible``: the
        single-precision solve as FGMRES (always on the contact set), which forms its solution from
        the preconditioned vectors and lets the measure stop build trial solutions (an exact step)."""
        self.ksp.setTolerances(rtol=rtol, atol=atol, max_it=-(-max_it // self.cycle))
        # not when the user chose the Krylov method (-ksp_type / -contact_ksp_type): theirs runs
        self.single = bool(single) and self.own_krylov()
        self.flexible = self.mode == "contact" or bool(flexible)
        self.mixed = bool(mixed) and not self.single
        self._tolerances = (rtol, atol, max_it)
        if not self.single and self._single is not None:
            self._single.free()           # the KSP's own basis takes the memory budget now

    def setUp(self, pc):
        pass

    def select(self, idx, n_S):
        """Make S the local points ``idx`` (flat, sorted), ``n_S`` points on all ranks (> 0)."""
        PETSc = self.PETSc
        n_loc = int(idx.size)
        self.idx = idx
        self.n_S = int(n_S)
        resize = self._A is None or self._A.getLocalSize()[0] != n_loc
        if self.comm.size > 1:   # collective: every rank must take the same branch
            resize = self.comm.allreduce(resize, op=MPI.LOR)
        if resize:
            if self._A is not None:
                self.ksp.reset()          # a KSP cannot change its operator's size otherwise
                for obj in (self._A, self._b, self._y):
                    obj.destroy()
            self._A_ctx = self.operator()
            self._A = PETSc.Mat().createPython(((n_loc, self.n_S), (n_loc, self.n_S)),
                                               context=self._A_ctx, comm=self.comm)
            self._A.setUp()
            self._b = self._A.createVecLeft()
            self._y = self._A.createVecRight()
        self.ksp.setOperators(self._A)
        if not self._configured:
            self.configure(self.defaults(n_loc))
            self._configured = True

    def configure(self, defaults, pc_context=None):
        """Put ``defaults`` into the options database under the inner prefix (where the user has not set
        the key; this step's own earlier defaults are replaced), then set the inner KSP from it.  A
        ``-pc_type ksp`` there nests it (free_cycle; its inner KSP and PC from the ``-ksp_ksp_*``
        options), and ``cycle`` becomes that KSP's iteration count, which it always runs in full.
        ``pc_context``: the Python PC of the inner KSP instead of ``preconditioner()`` (its ``cycle``, if
        it has one, counts)."""
        opts = self.PETSc.Options()
        for k, v in defaults.items():
            key = self._prefix + k
            if key in self._own_keys or not opts.hasName(key):
                opts[key] = v
                if key not in self._own_keys:
                    self._own_keys.append(key)
        pc = self.ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(self.step_pc() if pc_context is None else pc_context)
        self.ksp.setFromOptions()
        self.cycle = getattr(pc_context, "cycle", 1)
        if pc.getType() == "ksp":
            inner = pc.getKSP()
            inner.setFromOptions()
            self.cycle = inner.getTolerances()[3]

    def carry(self, unchanged):
        """Whether the next solve's set is the one the last solve ran on (``unchanged``; snes.py): an
        exact step then starts from the last solve's directions as they are (carry.py), a changing one
        from their map to its set (recycle.py, ``map_space``)."""
        self._unchanged = bool(unchanged)

    def maps_from(self, old):
        """Whether the directions of the last set (flat local points ``old``) are worth mapping to the
        current set (``map_space``); the base class: never.  Collective."""
        return False

    def map_space(self, space):
        """``space`` (a recycle.CarriedSpace of the last set) on the current set (the base class: no
        map, None).  Called only where ``maps_from`` said yes.  Collective."""
        return None

    def carries(self):
        """Whether the solves on the current set keep their directions for the next step and start from
        the last step's (carry.py, recycle.py): carry_directions > 0.  The same on every rank."""
        return self.settings.carry_directions > 0

    def solve(self):
        """Inner solve of A y = b (the vectors ``_b``, ``_y``) from y = 0."""
        if self.forcing:
            self.ksp.setTolerances(rtol=self._outer.getTolerances()[0])
        if self.single:
            self._solve_single()
        else:
            self._A_ctx.grid = self._krylov_grid()
            self._y.set(0.0)
            self.carried = self._carried_directions()
            try:
                self.ksp.solve(self._b, self._y)
                self.iterations += self.krylov_iterations(self.ksp.getIterationNumber())
                if self.carried is not None:
                    self.carried_directions += self.carried.served
            finally:
                self.carried = None
        self.solves += 1

    def krylov_iterations(self, its):
        """The Krylov iterations of ``its`` iterations of the running PETSc solve (self.ksp): ``cycle``
        each, less the carried directions, which cost no FFT pair (carry.py)."""
        return self.cycle * int(its) - (self.carried.served if self.carried is not None else 0)

    def _carried_directions(self):
        """CarriedDirections of the last solve (``carry``) for an exact PETSc solve on its set, or None;
        the last solve's memory is let go of.  Collective: every rank carries the same number."""
        # float32 products, like a mixed operator's, hold a solve near 1e-7 of its start: only where
        # the policy lets the operator round so (StepPolicy.mixed_reduction)
        if not (self._unchanged and self.cycle == 1 and self.mixed):
            self._carry_from = None
            return None
        space = self._last_space()
        if space is None:
            return None
        return CarriedDirections.of_space(space, self.fft, self.n_S, self.settings.carry_drop, self._b.getArray(readonly=True))

    def _last_space(self):
        """The directions of the last solve (recycle.CarriedSpace, on its set), or None; its memory is
        let go of.  Collective: every rank keeps the same number."""
        pending, self._carry_from = self._carry_from, None
        if pending is None or pending[0].arnoldi is None or not self.carries():
            return None
        gm, means, basis, older, idx = pending
        if not (self._unchanged or self.maps_from(idx)):
            return None                 # a changed set that no map serves: its copies would be wasted
        st = self.settings
        count = CarriedSpace.count(gm.n_loc, gm.Z.itemsize, st.carry_directions, st.carry_memory)
        count = self.comm.allreduce(count, op=MPI.MIN)
        return CarriedSpace.after_solve(gm, means, idx, count, basis, older) if count > 0 else None

    def _krylov_grid(self):
        """Where the PETSc solve's operator forms its products: with ``mixed`` (set_tolerances) and
        vecontact's own Krylov method, a float64 forward and a float32 backward transform (Mixed).  A z
        only enters the Krylov basis and the Newton residual is formed in float64 (snes.py), so its
        float32 rounding limits how far one solve can cut its residual (about 1e-7), not the answer
        (StepPolicy, mixed_reduction_max)."""
        return self.operator_mixed() if self.mixed and self.own_krylov() else self.grid

    def operator_mixed(self):
        """The operator's Mixed (float64 forward, float32 backward), one for the PETSc solves and the
        float32-basis ones; on ``work.float32_grid()``, so it does not mark the step as running float32
        pairs."""
        if self._mixed_grid is None:
            self._mixed_grid = Mixed(self.grid, self.work.float32_grid(), self)
        return self._mixed_grid

    def own_option(self, name):
        """Whether the inner KSP's option ``name`` (without prefix) is vecontact's default, not the user's."""
        return self._prefix + name in self._own_keys

    def own_krylov(self):
        """Whether the inner KSP's type is vecontact's default, not one the user chose (-ksp_type /
        -contact_ksp_type): only then may its solves change method or precision."""
        return self.own_option("ksp_type")

    def step_pc(self):
        """The inner KSP's Python PC: preconditioner() (ContactSetStep: in float32 where it may be)."""
        return self.preconditioner()

    def float32_grid(self):
        """The Grid on the SlabFFT's single-precision twin (made on first use)."""
        self._ran32 = True
        return self.work.float32_grid()

    def float32_pc(self):
        """Whether a preconditioner of a flexible method (FGMRES), which may round more than the
        operator, runs float32 pairs: the stiffness's range at most SolverSettings.pc_range_max."""
        return self.op.stiffness_range() <= self.settings.pc_range_max

    def float32_pairs_hold(self):
        """Whether a float32-basis solve runs float32 pairs too: the stiffness's range at most
        SolverSettings.single_range_max."""
        return self.op.stiffness_range() <= self.settings.single_range_max

    def single_context(self):
        """The step's _Single (made on first use; its pairs in float32 by the stiffness's range, and on
        the contact set, whose float32 steps are flexible, its preconditioner's by float32_pc)."""
        if self._single is None:
            self.float32_pairs = self.float32_pairs_hold()
            self._single = _Single(self, self.float32_pairs, self.mode == "contact" and self.float32_pc())
        return self._single

    def cycle_context(self):
        """The _Single of the float32 GMRES cycles (SingleCycles): single_context(), or, where its pairs
        are float64 and float32_pc holds, one with float32 pairs (a cycle is the preconditioner of an
        FGMRES whose operator stays float64)."""
        if self._cycles is None:
            sg = self.single_context()
            self._cycles = sg if self.float32_pairs or not self.float32_pc() else _Single(self, True)
        return self._cycles

    @property
    def ran_float32_pairs(self):
        """Whether this step's solves ran float32 pairs (steps, cycles or preconditioners: only they ask
        for the float32 Grid)."""
        return self._ran32

    def _solve_single(self):
        sg = self.single_context()
        n_loc = int(self.idx.size)
        rtol, atol, max_it = self._tolerances
        b, y = self._b.getArray(readonly=True), self._y.getArray()
        allsum = self.fft._allsum
        k = self.cycle
        space = self._last_space()      # before the bases' memory is reused
        # float64 vectors' worth of memory an iteration: a float32 basis vector, and with FGMRES the
        # preconditioned one in the work precision
        fgmres_vectors = (4 + np.dtype(sg.work).itemsize) / 8
        if k == 1:
            # the longest restart a flexible solve of this set may take: the stores are made for it, so
            # both fill the budget, never more (a step may turn flexible; its exact step does on the free set)
            flexible_restart = self.settings.single_restart(n_loc, self.mode, fgmres_vectors)
            own = flexible_restart if self.flexible else self.settings.single_restart(n_loc, self.mode, 0.5)
            restart = self.comm.allreduce(own, op=MPI.MIN)
            if not self.own_option("ksp_gmres_restart"):      # the user's restart
                restart = self.PETSc.Options().getInt(self._prefix + "ksp_gmres_restart")
            if space is not None and not self._unchanged:
                space = self.map_space(space)
            basis = space.basis(self.fft, self.n_S, self.settings.carry_drop) if space is not None else None
            gm = sg.gmres("plain", n_loc, min(restart, max_it), allsum, flexible=self.flexible,
                          capacity=flexible_restart)
            A, means = sg.A.matvec, None
            if gm.flexible and self.carries():
                means = []                      # what P took off each product: the raw products (recycle.py)

                def A(z, out, product=sg.A.matvec):
                    product(z, out)
                    means.append(self.removed)
            monitor = self.stop.monitor(self) if self.stop is not None and gm.flexible else None
            its, _ = gm.solve(A, sg.B.matvec, b, y, rtol, atol, max_it, carried=basis, monitor=monitor,
                              stall=self.settings.stall())
            self.stalls += gm.stalls
            if means is not None:               # its directions, for the next step (carry.py, recycle.py)
                self._carry_from = (gm, means, basis, space, self.idx)
            if basis is not None:
                self.carried_directions += basis.size
        else:   # cycles (freeset.start_cycles): FGMRES over exactly k GMRES iterations, as the KSP does
            restart = self.settings.single_restart(n_loc, "free", fgmres_vectors, reserve=k + 3)
            restart = self.comm.allreduce(restart, op=MPI.MIN)
            outer = sg.gmres("outer", n_loc, min(restart, -(-max_it // k)), allsum, flexible=True)
            its, _ = outer.solve(sg.A.matvec, SingleCycles(self, k).run, b, y, rtol, atol, -(-max_it // k))
            its *= k
        self.iterations += its
        self.single_iterations += its

    def release(self):
        """Destroy the inner KSP and its operators; remove the option defaults this step put in."""
        for obj in (self._A, self._b, self._y, self.ksp):
            if obj is not None:
                obj.destroy()
        self._A = self._b = self._y = self.ksp = self._A_ctx = self._mixed_grid = self._outer = None
        opts = self.PETSc.Options()
        for k in self._own_keys:
            try:
                opts.delValue(k)
            except Exception:
                pass
        self._own_keys = []
        self._single = self._cycles = self.work = self.grid = self.out = self.w = None
