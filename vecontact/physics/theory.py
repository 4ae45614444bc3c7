"""Persson's mean-field theory of viscoelastic contact and friction (docs/conventions.md §5).

For a rubber (modulus E(omega), Poisson ratio nu) sliding at velocity v over a rigid rough surface
with isotropic power spectrum C(q), under nominal pressure sigma0:

    G(q)  = (1/8) Int_{q0}^{q} dq' q'^3 C(q') Int_0^{2pi} dphi |E(q' v cos phi) / ((1-nu^2) sigma0)|^2
    P(q)  = erf(1 / (2 sqrt G(q)))            (P = 1 where G = 0),   A/A0 = P(q1)
    S(q)  = gamma + (1 - gamma) P(q)^2
    mu    = (1/2) Int_{q0}^{q1} dq q^3 C S P Int_0^{2pi} dphi cos(phi) Im E(q v cos phi) / ((1-nu^2) sigma0)
    xi^2  = 2 pi Int_{q0}^{q1} dq q^3 C(q) s(q, v),  s = (1/2pi) Int_0^{2pi} dphi |E(q v cos phi) / E0|^2

Numerics
--------
* Angle: both angular integrands are even about phi = 0 and about phi = pi/2, so
  Int_0^{2pi} = 4 Int_0^{pi/2}. Near phi = pi/2 the frequency q v cos phi -> 0, where real moduli
  are not analytic (Havriliak-Negami: E - E0 ~ omega^alpha), so Gauss-Legendre is applied after the
  substitution pi/2 - phi = (pi/2) x^4, x in [0, 1], which turns t^alpha end-point singularities into
  smooth x^(4 alpha) behaviour. ``nphi`` nodes on [0, pi/2].
* Wavenumber: composite Gauss-Legendre in ln q, panels of ``PANEL_ORDER`` nodes, never straddling a
  kink of C(q) (``spectrum.breakpoints``), ``nq`` nodes per decade of q (at least one panel per
  piece); the first panel is graded geometrically towards q0, where P(q) drops steeply at low
  pressure (without it mu erred by ~6e-4 at A/A0 ~ 1e-4). The running integral G(q) at the nodes
  uses the exact integral of the panel's
  interpolating polynomial (a spectral integration matrix), and A/A0 uses G(q1) from the full
  Gauss rule.
* G scales as 1/sigma0^2 and mu as 1/sigma0 once P is known, so the angular integrals and the
  running integral are computed once per velocity and then broadcast over the pressures.
"""
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TheoryResult", "persson", "mu_full_contact", "erf", "angular_integrals",
           "q_quadrature", "DEFAULT_NQ", "DEFAULT_NPHI"]

#: Default Gauss-Legendre nodes per decade of q (see tests/test_theory.py for the convergence).
DEFAULT_NQ = 48
#: Default angular nodes on [0, pi/2].
DEFAULT_NPHI = 32
#: Nodes per Gauss-Legendre panel in ln q.
PANEL_ORDER = 8
#: Geometric refinement of the first q panel towards q0: levels (at nq = DEFAULT_NQ; scaled with
#: nq) and ratio of successive panel widths.
GRADING_LEVELS = 6
GRADING_RATIO = 0.2
#: Power of the angular substitution pi/2 - phi = (pi/2) x^ANGLE_POWER.
ANGLE_POWER = 4


# --------------------------------------------------------------------------------------------
# erf without scipy: two Chebyshev interpolants of math.erf / math.erfc, built once at import.
# --------------------------------------------------------------------------------------------
_ERF_SPLIT = 1.5          # |x| < split: erf(x) = x R(x^2); split <= |x| < 6: erf = 1 - exp(-x^2) Q(1/x)
_ERF_XMAX = 6.0           # erf(x) = 1 to double precision for |x| >= 6 (erfc(6) = 2.2e-17)
_ERF_DEGREE = 18


def _chebyshev_fit(func, lo, hi):
    """Chebyshev coefficients of func (scalar -> float) on [lo, hi], interpolating at Chebyshev points."""
    def on_unit_interval(s):
        return np.array([func(lo + (hi - lo) * 0.5 * (v + 1.0)) for v in s])
    return np.polynomial.chebyshev.chebinterpolate(on_unit_interval, _ERF_DEGREE)


def _erf_over_x(y):
    """erf(x)/x as a function of y = x^2 (entire in y)."""
    x = math.sqrt(y)
    return math.erf(x) / x if x > 0 else 2.0 / math.sqrt(math.pi)


def _erfcx_of_inverse(t):
    """exp(x^2) erfc(x) as a function of t = 1/x (smooth and slowly varying for x >= 1.5)."""
    x = 1.0 / t
    return math.erfc(x) * math.exp(x * x)


_ERF_SMALL = _chebyshev_fit(_erf_over_x, 0.0, _ERF_SPLIT ** 2)
_ERF_LARGE = _chebyshev_fit(_erfcx_of_inverse, 1.0 / _ERF_XMAX, 1.0 / _ERF_SPLIT)


def erf(x):
    """Error function, vectorised in numpy; absolute error < 1e-14 (about 2e-15, see tests).

    |x| < 1.5: x R(x^2); 1.5 <= |x| < 6: 1 - exp(-x^2) Q(1/x); |x| >= 6: 1; odd in x; NaN propagates.
    R and Q are degree-18 Chebyshev interpolants of math.erf / math.erfc built at import.
    """
    x = np.asarray(x, dtype=float)
    ax = np.abs(x)
    value = np.where(np.isnan(ax), np.nan, 1.0)
    small = ax < _ERF_SPLIT
    if np.any(small):
        xs = ax[small]
        y = xs * xs * (2.0 / _ERF_SPLIT ** 2) - 1.0
        value[small] = xs * np.polynomial.chebyshev.chebval(y, _ERF_SMALL)
    large = (ax >= _ERF_SPLIT) & (ax < _ERF_XMAX)
    if np.any(large):
        xl = ax[large]
        lo, hi = 1.0 / _ERF_XMAX, 1.0 / _ERF_SPLIT
        s = (2.0 / xl - (lo + hi)) / (hi - lo)
        value[large] = 1.0 - np.exp(-xl * xl) * np.polynomial.chebyshev.chebval(s, _ERF_LARGE)
    return np.copysign(value, x)


# --------------------------------------------------------------------------------------------
# Quadrature rules
# --------------------------------------------------------------------------------------------
def _angle_rule(nphi):
    """Nodes cos(phi_j) and weights w_j with Int_0^{pi/2} f(phi) dphi ~ sum_j w_j f(phi_j)."""
    x, w = np.polynomial.legendre.leggauss(int(nphi))
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    p = ANGLE_POWER
    t = 0.5 * math.pi * x ** p                    # t = pi/2 - phi
    weights = 0.5 * math.pi * p * x ** (p - 1) * w
    return np.sin(t), weights                     # cos(phi) = sin(t)


def _panel_integration_matrix(order):
    """Gauss-Legendre nodes/weights on [-1, 1] and the matrix M with
    Int_{-1}^{x_i} f(x) dx ~ sum_j M_ij f(x_j) (exact for polynomials of degree < order)."""
    x, w = np.polynomial.legendre.leggauss(order)
    legendre = np.polynomial.legendre
    vandermonde = legendre.legvander(x, order - 1)                      # V_ik = P_k(x_i)
    integrated = np.column_stack([legendre.legval(x, legendre.legint(np.eye(order)[k], lbnd=-1))
                                  for k in range(order)])                # int_{-1}^{x_i} P_k
    return x, w, integrated @ np.linalg.inv(vandermonde)


def q_quadrature(spectrum, nq=None):
    """Composite Gauss-Legendre rule in ln q over the support of ``spectrum``.

    Returns a :class:`_QRule`: nodes ``q``, weights with Int f(q) dq ~ sum_i weights_i f(q_i), and
    ``running_integral(f)`` for Int_{q0}^{q_i} f dq at the nodes. ``nq`` is the number of nodes per
    decade of q; panels do not straddle ``spectrum.breakpoints``.
    """
    nq = DEFAULT_NQ if nq is None else nq
    x, w, matrix = _panel_integration_matrix(PANEL_ORDER)
    edges = []
    kinks = np.log(np.asarray(spectrum.breakpoints, dtype=float))
    for a, b in zip(kinks[:-1], kinks[1:]):
        n_panels = max(1, int(math.ceil(nq * (b - a) / math.log(10.0) / PANEL_ORDER)))
        edges.append(np.linspace(a, b, n_panels + 1)[:-1])
    # Grade the first panel geometrically towards q0: at low pressure P(q) falls from 1 within a
    # thin layer above q0 (G grows steeply there), which a uniform panel resolves poorly.
    first, rest = edges[0], edges[1:]
    first_width = (first[1] if first.size > 1 else kinks[1]) - first[0]
    levels = int(math.ceil(GRADING_LEVELS * nq / DEFAULT_NQ))        # refined together with nq
    levels = min(levels, int(math.log(1e-10) / math.log(GRADING_RATIO)))  # stay above rounding of ln q
    graded = first[0] + first_width * GRADING_RATIO ** np.arange(levels, 0, -1)
    starts = np.concatenate([first[:1], graded, first[1:]] + rest)
    widths = np.diff(np.append(starts, kinks[-1]))
    log_q = starts[:, None] + 0.5 * widths[:, None] * (x + 1.0)          # (panels, order)
    q = np.exp(log_q)
    weights = 0.5 * widths[:, None] * w * q                              # dq = q d(ln q)
    partial = 0.5 * widths[:, None, None] * matrix[None] * q[:, None, :]  # (panels, order, order)
    return _QRule(q.ravel(), weights.ravel(), weights, partial)


@dataclass
class _QRule:
    """Composite rule: nodes ``q`` (Q,), full weights ``weights`` (Q,), per-panel weights
    ``panel_weights`` (panels, order) and per-panel running-integral matrices ``partial``."""
    q: np.ndarray
    weights: np.ndarray
    panel_weights: np.ndarray
    partial: np.ndarray

    def running_integral(self, f):
        """Int_{q0}^{q_i} f dq at every node, for f (..., Q) -> (..., Q)."""
        n_panels, order = self.panel_weights.shape
        f = f.reshape(f.shape[:-1] + (n_panels, order))
        totals = np.einsum("...pj,pj->...p", f, self.panel_weights)
        before = np.cumsum(totals, axis=-1) - totals                     # integral up to panel start
        inside = np.einsum("pij,...pj->...pi", self.partial, f)
        return (before[..., None] + inside).reshape(f.shape[:-2] + (n_panels * order,))


def angular_integrals(modulus, q, velocities, nphi=None):
    """Angular integrals over phi in [0, 2 pi) at every (v, q):

    abs2[v, q] = Int dphi |E(q v cos phi)|^2            (Pa^2)
    loss[v, q] = Int dphi cos(phi) Im E(q v cos phi)   (Pa)
    """
    cos_phi, w = _angle_rule(DEFAULT_NPHI if nphi is None else nphi)
    omega = np.asarray(velocities, dtype=float)[:, None, None] * q[None, :, None] * cos_phi
    E = modulus(omega)
    abs2 = 4.0 * np.einsum("vqj,j->vq", E.real ** 2 + E.imag ** 2, w)
    loss = 4.0 * np.einsum("vqj,j->vq", E.imag, cos_phi * w)
    return abs2, loss


# --------------------------------------------------------------------------------------------
# The theory
# --------------------------------------------------------------------------------------------
@dataclass
class TheoryResult:
    """Persson theory on a (velocity, pressure) grid.

    q (Q,) quadrature nodes (1/m); P_q, G_q (V, P, Q); area (V, P) = A/A0 = P(q1);
    mu (V, P) viscoelastic friction coefficient; xi (V,) effective rms slope (dimensionless);
    slope_rms = sqrt(<|grad h|^2>); velocities (V,) m/s and pressures (P,) Pa as given; gamma.
    """
    q: np.ndarray
    P_q: np.ndarray
    G_q: np.ndarray
    area: np.ndarray
    mu: np.ndarray
    xi: np.ndarray
    slope_rms: float
    velocities: np.ndarray
    pressures: np.ndarray
    gamma: float


def _contact_probability(G):
    """P = erf(1 / (2 sqrt G)), with P = 1 where G = 0."""
    with np.errstate(divide="ignore"):
        return erf(0.5 / np.sqrt(np.maximum(G, 0.0)))


def persson(spectrum, modulus, velocities, pressures, gamma=0.5, nq=None, nphi=None):
    """Persson's theory for every velocity (m/s, shape V, >= 0) and nominal pressure (Pa, shape P).

    ``spectrum``: a roughness PSD (``vecontact.physics.spectrum``); ``modulus``: a model of
    ``vecontact.physics.modulus`` (its ``nu`` is used); ``gamma``: the S(q) parameter;
    ``nq`` nodes per decade of q and ``nphi`` angular nodes on [0, pi/2] (defaults converged to
    better than 1e-4 relative for the paper's parameters). Returns a :class:`TheoryResult`.
    """
    velocities, pressures = _as_grid(velocities, pressures)
    rule = q_quadrature(spectrum, nq)
    q = rule.q
    q3C = q ** 3 * spectrum(q)
    abs2, loss = angular_integrals(modulus, q, velocities, nphi)
    plane = 1.0 - modulus.nu ** 2

    # G at sigma0 = 1 Pa, running and at q1; then G = G1 / sigma0^2.
    integrand = q3C * abs2 / (8.0 * plane ** 2)                        # (V, Q)
    G1_q = rule.running_integral(integrand)
    G1_end = integrand @ rule.weights                                  # (V,)
    inv_s2 = 1.0 / pressures ** 2
    G_q = G1_q[:, None, :] * inv_s2[None, :, None]                     # (V, P, Q)
    P_q = _contact_probability(G_q)
    area = _contact_probability(G1_end[:, None] * inv_s2[None, :])

    S_q = gamma + (1.0 - gamma) * P_q ** 2
    friction = _friction_per_node(rule, q3C, loss, modulus.nu)          # (V, Q), at sigma0 = 1 Pa
    mu = np.einsum("vpq,vq->vp", S_q * P_q, friction) / pressures[None, :]

    xi = np.sqrt((q3C * abs2) @ rule.weights) / modulus.E0           # 2 pi s = abs2 / E0^2
    return TheoryResult(q=q, P_q=P_q, G_q=G_q, area=area, mu=mu, xi=xi,
                        slope_rms=math.sqrt(spectrum.slope2()), velocities=velocities,
                        pressures=pressures, gamma=float(gamma))


def mu_full_contact(spectrum, modulus, velocities, pressures, nq=None, nphi=None):
    """Friction coefficient in full contact (P = S = 1), shape (V, P):
    mu = (1/2) Int dq q^3 C(q) Int dphi cos(phi) Im E(q v cos phi) / ((1 - nu^2) sigma0)."""
    velocities, pressures = _as_grid(velocities, pressures)
    rule = q_quadrature(spectrum, nq)
    _, loss = angular_integrals(modulus, rule.q, velocities, nphi)
    friction = _friction_per_node(rule, rule.q ** 3 * spectrum(rule.q), loss, modulus.nu)
    return friction.sum(axis=-1)[:, None] / pressures[None, :]


def _as_grid(velocities, pressures):
    """Velocities (m/s) and pressures (Pa) as 1-D float arrays."""
    return (np.atleast_1d(np.asarray(velocities, dtype=float)).ravel(),
            np.atleast_1d(np.asarray(pressures, dtype=float)).ravel())


def _friction_per_node(rule, q3C, loss, nu):
    """Quadrature terms of mu at sigma0 = 1 Pa and P = S = 1: w_i (1/2) q^3 C loss / (1 - nu^2)."""
    return 0.5 * q3C * loss / (1.0 - nu ** 2) * rule.weights
