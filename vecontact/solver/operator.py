"""Nondimensional stiffness / compliance multipliers of the steady-sliding contact problem.

docs/conventions.md §4: for q != 0, p_q = M_q w_q with M_q = |q| E(q_x v) / (2 (1 - nu^2)); the q = 0
mode is the rigid-body position (load control).  Everything the iterative solvers see is
nondimensional:

* lengths (gap g, height h, displacement w) in units of ``ell`` = h_rms of the surface (dx for a
  flat surface),
* pressures in units of sigma0,

so the nondimensional stiffness is ``m_q = M_q ell / sigma0`` and the pressure of a gap field is

    p^(g^) = 1 + m (g^ + h^)           (m has a zero q = 0 mode, so mean(p^) = 1 exactly).

The "contact stiffness" ``k`` (Pa/m) that turns a gap into a pressure for the complementarity measure
and for the active-set choice of the semismooth Newton method is the diagonal of the real-space stiffness
matrix, i.e. the pressure at a grid point when that point alone is displaced by g:
``k = mean over the full q-grid of |M_q|`` (q = 0 included with M_0 = 0).  Nondimensionally
``kappa = k ell / sigma0``.

Convergence measures (scale-free; all three <= tolerance means converged):
  complementarity  max_x |min(p, k g)| / sigma0      (raw fields p(g), g of the iterate)
  penetration      max_x (-g) / h_rms
  force balance    |mean(p_out) - sigma0| / sigma0    (p_out = pressure returned: zero off contact)
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

__all__ = ["ContactOperator", "modulus_on_grid", "is_elastic_on_grid"]


def modulus_on_grid(fft, L, modulus, velocity):
    """E(q_x v) for the N values of q_x (shape (N, 1), complex)."""
    qx, _, _ = fft.wavevectors(L)
    omega = qx[:, 0] * float(velocity)
    E = np.asarray(modulus(omega), dtype=complex).reshape(-1)
    if E.shape[0] != fft.N:
        E = np.broadcast_to(E, (fft.N,)).copy()
    return E.reshape(fft.N, 1)


def is_elastic_on_grid(fft, L, modulus, velocity, rtol):
    """True when Im E(q_x v) == 0 (relative to |E|, rtol) for every q_x of the grid."""
    E = modulus_on_grid(fft, L, modulus, velocity)
    return bool(np.all(np.abs(E.imag) <= rtol * np.abs(E)))


class ContactOperator:
    """Multipliers and scaling of one problem on one grid.

    Attributes
    ----------
    fft, L, N, dx, sigma0, velocity, nu
    ell : length unit (m) = h_rms of h (dx if h is flat)
    hrms : rms height of h (m), mean_h : mean of h (m)
    E : E(q_x v), shape (N, 1) complex
    m : nondimensional stiffness  M ell / sigma0, with M = |q| E(q_x v) / (2 (1 - nu^2)) the dimensional
        stiffness multiplier (Pa/m), hermitian-fixed, local Fourier shape, M[q=0] = 0
    M, q : M (from m) and |q| (1/m), made on each use: a solve does not hold them
    c : nondimensional compliance 1/m (0 at q = 0)
    k : contact stiffness (Pa/m); kappa = k ell / sigma0
    hhat : (h - mean h) / ell  (local rows)
    p_h : m hhat (local rows), the pressure excess of full contact: p^(g^) = 1 + m g^ + p_h
    """

    def __init__(self, fft, L, modulus, velocity, sigma0, h, h_fourier=None):
        self.fft = fft
        self.L = float(L)
        self.N = N = fft.N
        self.dx = self.L / N
        self.sigma0 = float(sigma0)
        self.velocity = float(velocity)
        self.modulus = modulus
        self.nu = float(modulus.nu)
        if not self.sigma0 > 0:
            raise ValueError("sigma0 must be > 0")
        if self.velocity < 0:
            raise ValueError("velocity must be >= 0")
        h = np.asarray(h, dtype=float)
        if h.shape != fft.local_real_shape:
            raise ValueError(f"h: expected local shape {fft.local_real_shape}, got {h.shape}")
        self.mean_h = fft.mean(h)
        var = fft.sum((h - self.mean_h) ** 2) / float(N) ** 2
        self.hrms = float(np.sqrt(max(var, 0.0)))
        self.ell = self.hrms if self.hrms > 0 else self.dx

        qx, qy, q = fft.wavevectors(self.L)
        self.qx = qx
        self.E = modulus_on_grid(fft, self.L, modulus, self.velocity)
        M = q * self.E / (2.0 * (1.0 - self.nu ** 2))
        del q
        M = np.array(np.broadcast_to(M, fft.local_fourier_shape), dtype=complex, order="C")
        fft.hermitian_fix(M)
        if fft.col_start == 0:
            M[0, 0] = 0.0
        w = fft.half_weights()
        absM = np.abs(M)
        loc = float(np.sum(absM.sum(axis=0) * w[0]))
        self.k = fft.sum(np.array([loc])) / float(N) ** 2
        self.kappa = self.k * self.ell / self.sigma0
        M *= self.ell / self.sigma0
        self.m = M
        self._stiffness_bounds = None
        self._work = None       # whole-grid scratch of the measures and the active set (``work``)
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(absM > 0, 1.0 / np.where(absM > 0, self.m, 1.0), 0.0)
        self.c = np.ascontiguousarray(c)
        self.hhat = fft.real_array()
        np.multiply(h - self.mean_h, 1.0 / self.ell, out=self.hhat)
        # Fourier transform of h (SI), reused for p_h, the slope dh/dx and the coarse grids
        if h_fourier is None:
            h_fourier = fft.forward(h)
        self.h_fourier = h_fourier
        self.p_h = fft.real_array()
        fft.backward(h_fourier * (self.m / self.ell), self.p_h)   # m has M_0 = 0: mean(h) drops out

    @property
    def M(self):
        """The dimensional stiffness multiplier (Pa/m), M = m sigma0 / ell (a new array)."""
        return self.m * (self.sigma0 / self.ell)

    @property
    def q(self):
        """|q| (1/m), local Fourier shape (a new array)."""
        return self.fft.wavevectors(self.L)[2]

    def slope_x(self):
        """dh/dx (local rows, dimensionless), spectral; the x-Nyquist row is dropped."""
        m = 1j * self.qx * np.ones((1, self.fft.local_fourier_shape[1]))
        if self.N % 2 == 0:
            m[self.N // 2] = 0.0
        return self.fft.backward(self.h_fourier * m)

    def stiffness_bounds(self):
        """(min, max) of |m_q| over the grid's q != 0, all ranks (collective on the first call)."""
        if self._stiffness_bounds is None:
            a = np.abs(self.m)
            nz = a[a > 0]
            hi = self.fft.comm.allreduce(float(nz.max()) if nz.size else 0.0, op=MPI.MAX)
            lo = self.fft.comm.allreduce(float(nz.min()) if nz.size else np.inf, op=MPI.MIN)
            self._stiffness_bounds = (lo, hi)
        return self._stiffness_bounds

    def stiffness_range(self):
        """max |m_q| / min |m_q| over the grid's q != 0 (collective on the first call): how far float32
        rounding of a gap is amplified by the stiffness (single.py) and the policies that follow from
        it (SolverSettings.cycle_cap, pc_range_max, single_range_max)."""
        lo, hi = self.stiffness_bounds()
        return hi / lo if hi > 0 else 1.0

    def modulus_range(self):
        """max |E(q_x v)| / min |E(q_x v)| over the grid's q_x (1 for an elastic solid or at rest; no
        communication: every rank holds all q_x): how much of the stiffness's range is the rubber's,
        not the grid's, hence how far the contact set wanders between Newton steps solved on it
        (SolverSettings.step_area)."""
        a = np.abs(self.E)
        return float(a.max() / a.min())

    # ------------------------------------------------------------------ nondimensional maps
    def compliance_response(self):
        """c(x) on the local rows: the gap (h_rms) under a unit pressure (sigma0) at the origin, the
        compliance's kernel, (c p)(x) = sum_y c(x - y) p(y) (one FFT pair)."""
        return self._unit_response(self.c)

    def stiffness_response(self):
        """m(x) on the local rows: the pressure (sigma0) of a unit gap (h_rms) at the origin, the
        stiffness's kernel, (m g)(x) = sum_y m(x - y) g(y) (zero sum: m has no q = 0 mode; one FFT pair)."""
        return self._unit_response(self.m)

    def _unit_response(self, multiplier):
        fft = self.fft
        d = fft.real_array()
        d[...] = 0.0
        if fft.row_start == 0:
            d[0, 0] = 1.0
        return fft.apply(d, multiplier, d)

    def pressure(self, ghat, out=None):
        """p^ = 1 + m g^ + p_h (one FFT pair)."""
        out = self.fft.apply(ghat, self.m, out)
        out += self.p_h
        out += 1.0
        return out

    @property
    def work(self):
        """A real whole-grid scratch (local rows, made on first use), for passes over the grid that
        would otherwise allocate a temporary each call: its contents last until the next user."""
        if self._work is None:
            self._work = self.fft.real_array()
        return self._work

    def kappa_gap(self, ghat):
        """kappa g^ in ``work`` (the active set is {p^ >= kappa g^})."""
        return np.multiply(ghat, self.kappa, out=self.work)

    def measures(self, ghat, phat, active=None):
        """(complementarity, penetration, force) of the iterate (ghat, p^(ghat)), identical on all ranks.

        ``active``: bool mask of the contact set used to clean the returned pressure (default
        p^ >= kappa g^).  Three passes over the grid in ``work``, no temporaries (RESULTS.md, "The
        measures' passes")."""
        kg = self.kappa_gap(ghat)
        if active is None:
            active = phat >= kg
        comp = np.minimum(phat, kg, out=kg)               # |min(p^, kappa g^)|, by its extremes
        cmax = max(float(comp.max()), -float(comp.min())) if comp.size else 0.0
        pen = -float(ghat.min()) if ghat.size else 0.0
        pen = max(pen, 0.0)
        # force balance of the returned (cleaned) pressure: mean(p^ on the active set) - 1
        tot = self.fft.sum(np.multiply(phat, active, out=self.work))
        force = abs(tot / float(self.N) ** 2 - 1.0)
        buf = np.array([cmax, pen])
        out = np.empty(2)
        self.fft.comm.Allreduce(buf, out, op=MPI.MAX)
        return float(out[0]), float(out[1]), float(force)
