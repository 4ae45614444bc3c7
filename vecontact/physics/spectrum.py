"""Isotropic roughness power spectra C(q) in Persson's convention (docs/conventions.md §2).

C(q) = (2 pi)^-2 Int d^2x <h(x) h(0)> exp(-i q.x), in m^4, with q = |q| in 1/m, so that
h_rms^2 = 2 pi Int q C(q) dq and the (full 2-D) mean-square slope is
<|grad h|^2> = 2 pi Int q^3 C(q) dq. Both spectra here expose

* ``__call__(q)`` (vectorised), ``moment(n)`` = 2 pi Int q^(n+1) C(q) dq,
  ``hrms2()`` = moment(0), ``hrms()``, ``slope2()`` = moment(2);
* ``q_min``, ``q_max`` (the support) and ``breakpoints`` (the kinks of C, including the support
  ends, so that quadratures can be split into smooth pieces).
"""
import math

import numpy as np

__all__ = ["SelfAffine", "Tabulated", "line_psd", "isotropic_from_line", "LINE_TAIL_OCTAVES"]


def _power_integral(a, b, e):
    """Int_a^b q^e dq for 0 < a <= b (exact, including e = -1)."""
    if a >= b:
        return 0.0
    if abs(e + 1.0) < 1e-12:
        return math.log(b / a)
    return (b ** (e + 1.0) - a ** (e + 1.0)) / (e + 1.0)


#: Relative tolerance on the band edges q0 and q1 (see SelfAffine.__call__).
EDGE_RTOL = 1e-9

class _Spectrum:
    """Common derived quantities; subclasses provide ``moment`` and ``__call__``."""

    def hrms2(self):
        """Mean-square height h_rms^2 = 2 pi Int q C dq (m^2)."""
        return self.moment(0)

    def hrms(self):
        """Root-mean-square height (m)."""
        return math.sqrt(self.hrms2())

    def slope2(self):
        """Mean-square slope <|grad h|^2> = 2 pi Int q^3 C dq (full 2-D gradient, dimensionless)."""
        return self.moment(2)


class SelfAffine(_Spectrum):
    """Self-affine spectrum with roll-off (the paper's surfaces).

    C(q) = C0 for q0 <= q <= qr, C0 (q / qr)^(-2 (1 + H)) for qr < q <= q1, 0 elsewhere.
    q0, qr, q1 in 1/m with q0 <= qr <= q1 (qr == q0: no roll-off), Hurst exponent H, C0 in m^4.
    """

    def __init__(self, q0, qr, q1, hurst, C0):
        self.q0, self.qr, self.q1 = float(q0), float(qr), float(q1)
        self.hurst = float(hurst)
        self.C0 = float(C0)
        if not (0 < self.q0 <= self.qr <= self.q1):
            raise ValueError("need 0 < q0 <= qr <= q1")
        if self.q0 == self.q1:
            raise ValueError("need q0 < q1")

    @classmethod
    def from_hrms(cls, q0, qr, q1, hurst, hrms):
        """The spectrum whose C0 gives the rms height ``hrms`` (m)."""
        unit = cls(q0, qr, q1, hurst, 1.0)
        return cls(q0, qr, q1, hurst, float(hrms) ** 2 / unit.hrms2())

    @property
    def exponent(self):
        """Power-law exponent of the self-affine tail, C ~ q^exponent = q^(-2 (1 + H))."""
        return -2.0 * (1.0 + self.hurst)

    @property
    def q_min(self):
        return self.q0

    @property
    def q_max(self):
        return self.q1

    @property
    def breakpoints(self):
        """Kinks of C(q): [q0, qr, q1] ([q0, q1] without roll-off)."""
        kinks = [self.q0]
        for q in (self.qr, self.q1):
            if q > kinks[-1]:
                kinks.append(q)
        return kinks

    def __call__(self, q):
        q = np.asarray(q, dtype=float)
        with np.errstate(divide="ignore"):
            tail = self.C0 * (np.maximum(q, self.qr) / self.qr) ** self.exponent
        # Band edges with a relative slack of EDGE_RTOL: lattice wavevectors k 2 pi / L on the
        # edge circles differ from k q0 by rounding and must not drop out at random.
        inside = (q >= self.q0 * (1 - EDGE_RTOL)) & (q <= self.q1 * (1 + EDGE_RTOL))
        return np.where(inside, np.where(q <= self.qr, self.C0, tail), 0.0)

    def moment(self, n):
        """2 pi Int q^(n+1) C(q) dq in closed form (m^(2-n))."""
        flat = _power_integral(self.q0, self.qr, n + 1.0)
        tail = self.qr ** (-self.exponent) * _power_integral(self.qr, self.q1, n + 1.0 + self.exponent)
        return 2.0 * math.pi * self.C0 * (flat + tail)

    def describe(self):
        return (f"self-affine: q0 = {self.q0:.4g}, qr = {self.qr:.4g}, q1 = {self.q1:.4g} 1/m, "
                f"H = {self.hurst:g}, C0 = {self.C0:.5g} m^4, h_rms = {self.hrms() * 1e9:.4g} nm, "
                f"rms slope = {math.sqrt(self.slope2()):.4g}")


class Tabulated(_Spectrum):
    """PSD given on samples (q_k, C_k), e.g. the radial average of a measured surface.

    q strictly increasing and positive (1/m), C positive (m^4). Between samples C is interpolated
    linearly in (log q, log C), i.e. as a power law; C = 0 outside [q[0], q[-1]]. Moments are the
    exact integrals of that piecewise power law, so they are consistent with ``__call__``.
    """

    def __init__(self, q, C):
        self.q = np.asarray(q, dtype=float).ravel()
        self.C = np.asarray(C, dtype=float).ravel()
        if self.q.size < 2 or self.q.shape != self.C.shape:
            raise ValueError("q and C must be 1-D arrays of equal length >= 2")
        if np.any(self.q <= 0) or np.any(np.diff(self.q) <= 0):
            raise ValueError("q must be positive and strictly increasing")
        if np.any(self.C <= 0):
            raise ValueError("C must be positive (log-log interpolation)")
        self._log_q = np.log(self.q)
        self._log_C = np.log(self.C)
        # Local power-law exponents C ~ q^slope on each interval.
        self._slopes = np.diff(self._log_C) / np.diff(self._log_q)

    @classmethod
    def from_surface(cls, fft, h, L):
        """The radially averaged PSD of the surface ``h`` (local rows of a :class:`SlabFFT` grid,
        heights in m, period L in m): unit-width annuli in 2 pi / L, empty or zero bins dropped
        (``SlabFFT.radial_psd``). Same result on every rank. ValueError if the surface is flat."""
        q, C = fft.radial_psd(h, L)
        keep = C > 0
        if keep.sum() < 2:
            raise ValueError("the surface is flat: its power spectrum is zero")
        return cls(q[keep], C[keep])

    def band(self, lo, hi):
        """The spectrum restricted to [lo, hi] (1/m): C = 0 outside; the end points are
        interpolated (log-log) when they fall between samples. ValueError if the band misses the
        table or is narrower than a point."""
        lo, hi = max(float(lo), self.q_min), min(float(hi), self.q_max)
        if not lo < hi:
            raise ValueError(f"the band [{lo:g}, {hi:g}] 1/m leaves the table ({self.q_min:g} .. {self.q_max:g})")
        inner = (self.q > lo) & (self.q < hi)
        q = np.concatenate([[lo], self.q[inner], [hi]])
        return Tabulated(q, self(q))

    @property
    def q_min(self):
        return float(self.q[0])

    @property
    def q_max(self):
        return float(self.q[-1])

    @property
    def breakpoints(self):
        """Every sample is a kink of the log-log interpolant."""
        return [float(x) for x in self.q]

    def __call__(self, q):
        q = np.asarray(q, dtype=float)
        # the same slack at the ends as SelfAffine: lattice wavevectors on an end circle stay in
        inside = (q >= self.q[0] * (1 - EDGE_RTOL)) & (q <= self.q[-1] * (1 + EDGE_RTOL))
        log_q = np.log(np.clip(q, self.q[0], self.q[-1]))
        return np.where(inside, np.exp(np.interp(log_q, self._log_q, self._log_C)), 0.0)

    def moment(self, n):
        """2 pi Int q^(n+1) C(q) dq, exact for the piecewise power law (m^(2-n))."""
        a, b = self.q[:-1], self.q[1:]
        e = n + 1.0 + self._slopes           # integrand q^(n+1) C_a (q/a)^slope ~ q^e
        ratio = b / a
        with np.errstate(divide="ignore", invalid="ignore"):
            generic = a ** (n + 2.0) * self.C[:-1] * np.expm1((e + 1.0) * np.log(ratio)) / (e + 1.0)
        logarithmic = a ** (n + 2.0) * self.C[:-1] * np.log(ratio)
        pieces = np.where(np.abs(e + 1.0) < 1e-12, logarithmic, generic)
        return 2.0 * math.pi * float(pieces.sum())

    def describe(self):
        return (f"tabulated PSD: {self.q.size} samples, q {self.q[0]:.4g}..{self.q[-1]:.4g} 1/m, "
                f"h_rms = {self.hrms() * 1e9:.4g} nm, rms slope = {math.sqrt(self.slope2()):.4g}")


# --------------------------------------------------------------------------------------------
# 1-D line-scan spectra (docs/inputs.md, "1-D line-scan spectra")
#
# C1D(q) = (1/2 pi) Int dx <h(x) h(0)> exp(-i q x) (m^3), two-sided: h_rms^2 = Int_{-inf}^{inf} C1D dq.
# For an isotropic surface with Persson's 2-D C(q), C1D(qx) = Int dqy C(sqrt(qx^2 + qy^2)), and
# the Abel inversion gives C(q) = -(1/pi) Int_q^inf dk C1D'(k) / sqrt(k^2 - q^2).
# Both integrals are done in t with k = q cosh t (dk / sqrt(k^2 - q^2) = dt), which removes the
# inverse square-root singularity at k = q; Gauss-Legendre panels never straddle a kink.

#: Gauss-Legendre nodes per panel and largest panel width in t of the line-spectrum integrals.
_LINE_ORDER = 16
_LINE_PANEL = 0.25
#: Octaves at the large-q end of a line-scan table over which the tail exponent is fitted.
LINE_TAIL_OCTAVES = 1.0


def _t_panels(edges):
    """Gauss-Legendre nodes and weights in t over consecutive intervals [edges[i], edges[i+1]]
    (1-D array, non-decreasing), each split into panels of width <= _LINE_PANEL. Returns (t, w)."""
    x, w = np.polynomial.legendre.leggauss(_LINE_ORDER)
    width = np.diff(edges)
    keep = width > 0
    starts, width = edges[:-1][keep], width[keep]
    n = np.maximum(1, np.ceil(width / _LINE_PANEL)).astype(int)
    half = np.repeat(0.5 * width / n, n)                              # half-width of each panel
    panel = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)       # index within its interval
    a = np.repeat(starts, n) + 2.0 * half * panel
    return (a[:, None] + half[:, None] * (x + 1.0)).ravel(), (half[:, None] * w).ravel()


def line_psd(spectrum, q):
    """The 1-D line-scan PSD C1D(q) (m^3) of an isotropic surface with 2-D spectrum ``spectrum``
    (Persson's convention, m^4), at wavevectors q > 0 (1/m, array):

    C1D(q) = Int dqy C(sqrt(q^2 + qy^2)) = 2 Int_{max(q, q_min)}^{q_max} C(k) k / sqrt(k^2 - q^2) dk.
    """
    q = np.atleast_1d(np.asarray(q, dtype=float))
    if np.any(q <= 0):
        raise ValueError("line_psd needs wavevectors q > 0")
    kinks = np.asarray(spectrum.breakpoints, dtype=float)
    out = np.empty(q.shape)
    for i, qi in enumerate(q.ravel()):
        inside = kinks[kinks > qi]
        edges = np.arccosh(np.concatenate([[max(qi, kinks[0])], inside]) / qi)
        t, w = _t_panels(edges)
        k = qi * np.cosh(t)
        out.flat[i] = 2.0 * np.sum(w * spectrum(k) * k)
    return out


def isotropic_from_line(q, C1D):
    """Persson's 2-D C(q) (m^4) at the samples q (1/m) from a measured line-scan PSD (q, C1D) (m^3).

    C1D is interpolated as a power law between samples (as :class:`Tabulated` does) and continued
    beyond the last sample as a power law whose exponent is fitted (least squares in log-log) to
    the samples in the last ``LINE_TAIL_OCTAVES`` octave(s); the Abel inversion
    C(q) = -(1/pi) Int_q^inf C1D'(k) / sqrt(k^2 - q^2) dk is then exact for that model up to the
    quadrature (16-point Gauss-Legendre panels of width <= 0.25 in t = arccosh(k / q); the tail in
    closed form, an incomplete beta function). Returns C at every sample (it can come out <= 0 where
    the data rise with q; the caller decides). ValueError if the fitted tail does not decay.
    """
    from scipy.special import beta as beta_fn, betainc
    q = np.asarray(q, dtype=float)
    C1D = np.asarray(C1D, dtype=float)
    line = Tabulated(q, C1D)                      # validates: increasing q, positive C
    slopes = line._slopes                         # C1D ~ k^s on each interval
    tail = q >= q[-1] * 2.0 ** -LINE_TAIL_OCTAVES
    if tail.sum() < 2:
        tail[-2:] = True
    s_tail = float(np.polyfit(np.log(q[tail]), np.log(C1D[tail]), 1)[0])
    if s_tail >= 0:
        raise ValueError(f"the line-scan PSD does not decay at its large-q end (fitted exponent "
                         f"{s_tail:.3g} over the last octave): its tail cannot be continued")
    out = np.empty(q.shape)
    for j, qj in enumerate(q):
        edges = np.arccosh(q[j:] / qj)            # sample k_i = q cosh t_i, i >= j
        t, w = _t_panels(edges)
        k = qj * np.cosh(t)
        piece = np.minimum(np.searchsorted(q, k, side="right") - 1, q.size - 2)
        body = np.sum(w * slopes[piece] * line(k) / k)
        # tail: Int_{q_max}^inf s C_end (k/q_max)^s / k / sqrt(k^2 - q^2) dk
        #     = s C_end (q / q_max)^s / q * (1/2) B(x^2; (1 - s)/2, 1/2),  x = q / q_max
        a = 0.5 * (1.0 - s_tail)
        x2 = (qj / q[-1]) ** 2
        tail_int = s_tail * C1D[-1] * (qj / q[-1]) ** s_tail / qj * 0.5 * betainc(a, 0.5, x2) * beta_fn(a, 0.5)
        out[j] = -(body + tail_int) / math.pi
    return out
