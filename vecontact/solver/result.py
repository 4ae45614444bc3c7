"""ContactResult and the scalar post-processing (docs/conventions.md §4).

* area          A/A0 = fraction of grid points with p > 0 (the returned pressure is exactly 0 off contact)
* mu            dissipation estimate  sum_{q != 0} |q| q_x E''(q_x v) |w_q|^2 / (2 (1 - nu^2) sigma0),
                w_q = forward(w)/N^2.  The sum uses the operator's own multiplier, i.e. E'' is taken as 0
                on the x-Nyquist row (hermitian_fix), so that mu equals the dissipated power of the
                discrete operator; for band-limited fields (null band) this is the formula exactly.
* mu_geometric  <p dh/dx> / sigma0 with the spectral x-derivative of h
* mean_gap      <g> (m);  rigid_position delta = <z> = <g> + <h> (m) (z = w + delta, <w> = 0)

``fft_pairs`` is the number of forward+backward FFT pairs in fine-grid equivalents: a transform on a grid
of N' points per side counts (N'/N)^2 log(N'^2)/log(N^2) of a fine one (the FFT flop ratio); one
forward or backward transform counts 1/2.  Everything done by the call (set-up, coarse grids,
iterations, post-processing) is counted; ``fft_pairs_by_level`` gives the raw (unweighted) pairs per
grid size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

__all__ = ["ContactResult", "pair_weight", "postprocess"]


def pair_weight(n_level, n_fine):
    """Fine-grid equivalent of one FFT pair on an n_level grid."""
    if n_level == n_fine:
        return 1.0
    return (n_level / n_fine) ** 2 * math.log(n_level ** 2) / math.log(n_fine ** 2)


@dataclass
class ContactResult:
    area: float
    mu: float
    mu_geometric: float
    mean_gap: float
    rigid_position: float
    converged: bool
    iterations: int
    linear_iterations: int
    fft_pairs: float
    residual: float
    seconds: float
    reason: str
    method: str
    pressure: Optional[np.ndarray] = None
    gap: Optional[np.ndarray] = None
    displacement: Optional[np.ndarray] = None
    fft_pairs_by_level: dict = field(default_factory=dict)
    measures: dict = field(default_factory=dict)
    sigma0: float = 0.0
    velocity: float = 0.0
    N: int = 0
    L: float = 0.0
    diagnostics: dict = field(default_factory=dict)
    # warm-start state (local rows, SI): the gap and pressure of the solution
    warm_state: Any = field(default=None, repr=False)

    def summary(self):
        return (f"{self.method}: N={self.N} A/A0={self.area:.5g} mu={self.mu:.5g} "
                f"mu_geo={self.mu_geometric:.5g} converged={self.converged} it={self.iterations} "
                f"lin={self.linear_iterations} pairs={self.fft_pairs:.1f} res={self.residual:.2e} "
                f"t={self.seconds:.2f}s ({self.reason})")


def postprocess(op, p_out, g_out, displacement=True):
    """Scalars of the SI fields p_out (Pa), g_out (m) on op's grid. Returns (dict, w) with w (m) the
    displacement, or None when ``displacement`` is False (mu needs only its spectrum: half a pair less)."""
    fft = op.fft
    n2 = float(op.N) ** 2
    npos = np.count_nonzero(p_out > 0)
    dhdx = op.slope_x()
    s_npos, s_g, s_pdh = (fft.sum(np.array([x])) for x in (float(npos), float(np.sum(g_out)),
                                                          float(np.sum(p_out * dhdx))))
    area = s_npos / n2
    mean_gap = s_g / n2
    rigid = mean_gap + op.mean_h
    mu_geo = s_pdh / n2 / op.sigma0
    # displacement w = g + h - delta (zero mean)
    Gq = fft.forward(g_out)
    Wq = (Gq + op.h_fourier) / n2
    if fft.col_start == 0:
        Wq[0, 0] = 0.0
    w = fft.backward(Wq * n2) if displacement else None
    # dissipation: sum over full spectrum of q_x Im(M_q) |w_q|^2 / sigma0, with Im(M) / sigma0 = Im(m) / ell
    dens = (op.qx * op.m.imag) * (Wq.real ** 2 + Wq.imag ** 2)
    loc = float(np.sum(dens.sum(axis=0) * fft.half_weights()[0]))
    mu = fft.sum(np.array([loc])) / op.ell
    return dict(area=area, mean_gap=mean_gap, rigid_position=rigid, mu_geometric=mu_geo, mu=mu), w
