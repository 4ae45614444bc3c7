"""Dense direct reference solver for the discrete steady-sliding contact problem (small grids).

Written independently of ``vecontact.solver`` from docs/conventions.md sections 1 and 4 only:

* grid N x N, side L, x = (i, j) dx, axis 0 = x = sliding direction;
* h_q = fft2(h) / N^2, q = 2 pi / L (m, n) in numpy's fftfreq order;
* for q != 0: p_q = M_q w_q, M_q = |q| E(q_x v) / (2 (1 - nu^2)); on the x-Nyquist row
  (m = -N/2, N even) Re(M_q) is used so that the operator maps real fields to real fields;
* q = 0: rigid-body position delta, fixed by mean(p) = sigma0;
* gap g = w + delta - h >= 0, p >= 0, p g = 0.

Here w is taken with zero mean, so delta is the mean position of the rubber surface and
mean(g) = delta - mean(h).

The compliance operator w = K p (w_q = p_q / M_q for q != 0, w_0 = 0) is a periodic convolution;
its real N^2 x N^2 matrix is built explicitly (from the kernel ifft2(1/M_q), or column by column
by applying the Fourier definition to unit vectors) and the linear complementarity problem is
solved by a direct active-set method:

1. start from full contact S = all points;
2. solve the equality system K_SS p_S + delta = h_S, sum(p_S) = N^2 sigma0 (p = 0 off S);
3. if some p_S < 0: remove them from S (all at once; the most negative only once a cycle is
   detected) and go to 2;
4. else if some g < 0 off S: add them to S (all at once, or the most penetrating only) and go to 2;
5. else stop: p >= 0 on S, g = 0 on S, p = 0 and g >= 0 off S is an exact solution.

The non-symmetric (viscoelastic) compliance has a positive definite symmetric part on zero-mean
fields (Re(1/M_q) = 2 (1 - nu^2) E' / (|q| |E|^2) > 0), so the LCP has a unique solution, which the
fixed point of the iteration is. Problems up to 48^2 = 2304 unknowns take a few seconds.

A 1-D variant (:func:`dense_solve_1d`) solves the same discrete problem for heights independent
of y: by uniqueness the 2-D solution is then independent of y and equals the 1-D one, which allows
exact discrete references for Westergaard-type problems on N up to ~1024.
"""
from dataclasses import dataclass, field

import numpy as np

__all__ = ["wavevectors", "multiplier", "apply_stiffness", "apply_compliance", "compliance_matrix",
           "dense_solve", "dense_solve_1d", "mu_dissipation", "mu_geometric", "DenseResult",
           "random_surface", "spectral_dx", "multiplier_1d"]


# ----------------------------------------------------------------------------- operator

def wavevectors(N, L):
    """(qx, qy) on the N x N grid, indexing 'ij' (axis 0 = x), numpy fftfreq ordering (1/m)."""
    q = 2.0 * np.pi * np.fft.fftfreq(N, d=L / N)
    qx, qy = np.meshgrid(q, q, indexing="ij")
    return qx, qy


def _xnyquist_rows(N):
    """Index of the x-Nyquist row (m = -N/2) for even N, else None."""
    return N // 2 if N % 2 == 0 else None


def multiplier(N, L, modulus, nu, velocity):
    """M_q = |q| E(q_x v) / (2 (1 - nu^2)) (N x N complex, Pa/m); M_0 = 0; x-Nyquist row real."""
    qx, qy = wavevectors(N, L)
    qabs = np.hypot(qx, qy)
    E = np.asarray(modulus(qx * velocity), dtype=complex) * np.ones_like(qx)
    M = qabs * E / (2.0 * (1.0 - nu ** 2))
    nyq = _xnyquist_rows(N)
    if nyq is not None:
        M[nyq, :] = M[nyq, :].real
    M[0, 0] = 0.0
    return M


def multiplier_1d(N, L, modulus, nu, velocity):
    """1-D version for y-independent fields: M_m = |q_x| E(q_x v) / (2 (1 - nu^2))."""
    qx = 2.0 * np.pi * np.fft.fftfreq(N, d=L / N)
    E = np.asarray(modulus(qx * velocity), dtype=complex) * np.ones_like(qx)
    M = np.abs(qx) * E / (2.0 * (1.0 - nu ** 2))
    nyq = _xnyquist_rows(N)
    if nyq is not None:
        M[nyq] = M[nyq].real
    M[0] = 0.0
    return M


def _compliance_symbol(M):
    C = np.zeros_like(M)
    nz = M != 0
    C[nz] = 1.0 / M[nz]
    return C


def apply_stiffness(w, M):
    """p - mean(p) = M w (real field in, real field out)."""
    out = np.fft.ifftn(M * np.fft.fftn(w))
    return out.real


def apply_compliance(p, M):
    """Zero-mean displacement w = K p (w_q = p_q / M_q, w_0 = 0)."""
    out = np.fft.ifftn(_compliance_symbol(M) * np.fft.fftn(p))
    return out.real


def compliance_matrix(M, method="kernel"):
    """Explicit real matrix K (n x n, n = M.size) with w.ravel() = K @ p.ravel().

    method="kernel": K[a, b] = k[(x_a - x_b) mod N] with k = ifft(1/M) (periodic convolution);
    method="columns": column b = the Fourier definition applied to the unit vector e_b.
    """
    C = _compliance_symbol(M)
    if method == "columns":
        shape = M.shape
        n = M.size
        eye = np.eye(n).reshape((n,) + shape)
        axes = tuple(range(1, len(shape) + 1))
        cols = np.fft.ifftn(C * np.fft.fftn(eye, axes=axes), axes=axes)
        if np.abs(cols.imag).max() > 1e-12 * np.abs(cols.real).max():
            raise ValueError("compliance operator does not map real to real")
        return np.ascontiguousarray(cols.real.reshape(n, n).T)
    return _convolution_matrix(C, "compliance")


def stiffness_matrix(M):
    """Explicit real matrix S (n x n) with (p - mean p).ravel() = S @ w.ravel(): the periodic convolution
    with the stiffness's kernel ifft(M) (S has no q = 0 mode: its rows sum to zero)."""
    return _convolution_matrix(M, "stiffness")


def _convolution_matrix(symbol, name):
    """The matrix of the periodic convolution whose Fourier symbol is ``symbol`` (1-D or 2-D)."""
    shape = symbol.shape
    kern = np.fft.ifftn(symbol)
    if np.abs(kern.imag).max() > 1e-12 * np.abs(kern.real).max():
        raise ValueError(f"{name} kernel is not real (Nyquist handling?)")
    kern = kern.real
    if len(shape) == 1:
        N = shape[0]
        i = np.arange(N)
        return kern[(i[:, None] - i[None, :]) % N]
    N0, N1 = shape
    di = (np.arange(N0)[:, None] - np.arange(N0)[None, :]) % N0
    dj = (np.arange(N1)[:, None] - np.arange(N1)[None, :]) % N1
    K4 = kern[di[:, None, :, None], dj[None, :, None, :]]  # [ia, ja, ib, jb]
    return K4.reshape(symbol.size, symbol.size)


# ----------------------------------------------------------------------------- friction

def mu_dissipation(w, L, modulus, nu, velocity, sigma0, literal=False):
    """Dissipation estimate of mu (docs/conventions.md §4) from the displacement field w (any mean).

    Default (``literal=False``): sum_{q != 0} q_x Im(M_q) |w_q|^2 / sigma0 with M_q exactly as the
    operator uses it (x-Nyquist row real, so no dissipation there); this equals <p dh/dx>/sigma0
    in full contact. ``literal=True``: the formula with E''(q_x v) on every row, Nyquist included.
    """
    w = np.asarray(w, dtype=float)
    N = w.shape[0]
    wq = np.fft.fftn(w) / w.size
    if w.ndim == 1:
        qx = 2.0 * np.pi * np.fft.fftfreq(N, d=L / N)
        qabs = np.abs(qx)
        M = multiplier_1d(N, L, modulus, nu, velocity)
    else:
        qx, qy = wavevectors(N, L)
        qabs = np.hypot(qx, qy)
        M = multiplier(N, L, modulus, nu, velocity)
    if literal:
        Epp = np.asarray(modulus(qx * velocity), dtype=complex).imag * np.ones_like(qx)
        terms = qabs * qx * Epp * np.abs(wq) ** 2 / (2.0 * (1.0 - nu ** 2))
    else:
        terms = qx * M.imag * np.abs(wq) ** 2
    terms.flat[0] = 0.0
    return float(terms.sum() / sigma0)


def spectral_dx(h, L):
    """dh/dx by spectral differentiation (x-Nyquist row set to zero so the result is real)."""
    h = np.asarray(h, dtype=float)
    N = h.shape[0]
    qx = 2.0 * np.pi * np.fft.fftfreq(N, d=L / N)
    if h.ndim == 2:
        qx = qx[:, None] * np.ones((1, h.shape[1]))
    mult = 1j * qx
    nyq = _xnyquist_rows(N)
    if nyq is not None:
        mult[nyq] = 0.0
    return np.fft.ifftn(mult * np.fft.fftn(h)).real


def mu_geometric(p, h, L, sigma0):
    """Geometric estimate mu = mean(p dh/dx) / sigma0."""
    return float(np.mean(p * spectral_dx(h, L)) / sigma0)


# ----------------------------------------------------------------------------- LCP

@dataclass
class DenseResult:
    pressure: np.ndarray          # Pa
    displacement: np.ndarray      # zero-mean w (m)
    gap: np.ndarray               # m
    rigid_position: float         # delta (m): g = w + delta - h
    mean_gap: float               # m
    area: float                   # fraction of points with p > 0
    mu: float                     # dissipation estimate (operator-consistent)
    mu_literal: float             # dissipation estimate with E'' on the Nyquist row too
    mu_geometric: float
    iterations: int
    complementarity: float        # max |p g| / (sigma0 * h_scale)
    min_pressure: float           # / sigma0 (>= 0 up to round-off)
    min_gap: float                # / h_scale
    load_error: float             # |mean p - sigma0| / sigma0
    n_degenerate: int             # points with p and g both ~0 (1e-9 relative): area ambiguity
    history: list = field(default_factory=list)


def _active_set(K, H, max_iter=None, tol=1e-11):
    """Solve the load-controlled LCP in nondimensional form.

    K (n x n): compliance (gap per unit pressure), H (n): heights; mean(P) = 1.
    Returns P, G, delta, iterations, history.
    """
    n = H.size
    S = np.ones(n, dtype=bool)
    seen = set()
    single = False
    history = []
    max_iter = max_iter or 20 * n + 100
    for it in range(1, max_iter + 1):
        idx = np.flatnonzero(S)
        m = idx.size
        A = np.empty((m + 1, m + 1))
        A[:m, :m] = K[np.ix_(idx, idx)]
        A[:m, m] = 1.0
        A[m, :m] = 1.0
        A[m, m] = 0.0
        rhs = np.empty(m + 1)
        rhs[:m] = H[idx]
        rhs[m] = n
        sol = np.linalg.solve(A, rhs)
        P = np.zeros(n)
        P[idx] = sol[:m]
        delta = sol[m]
        G = K @ P + delta - H
        G[idx] = 0.0
        pscale = max(1.0, P.max())
        neg = S & (P < -tol * pscale)
        pen = (~S) & (G < -tol)
        history.append((m, int(neg.sum()), int(pen.sum())))
        if not neg.any() and not pen.any():
            return P, G, delta, it, history
        key = np.packbits(S).tobytes()
        if key in seen:
            single = True
        seen.add(key)
        if neg.any():
            if single:
                S[idx[np.argmin(P[idx])]] = False
            else:
                S[neg] = False
        else:
            if single:
                out = np.flatnonzero(~S)
                S[out[np.argmin(G[out])]] = True
            else:
                S[pen] = True
    raise RuntimeError(f"dense active set did not converge in {max_iter} iterations")


def _solve(h, L, modulus, nu, velocity, sigma0, M, method):
    h = np.asarray(h, dtype=float)
    hs = float(h.max() - h.min())
    if hs == 0.0:
        hs = 1.0
    K = compliance_matrix(M, method=method) * (sigma0 / hs)
    P, G, delta, its, history = _active_set(K, (h / hs).ravel())
    P = P.reshape(h.shape)
    G = G.reshape(h.shape)
    p_nd = np.where(P > 0, P, 0.0)
    pressure = p_nd * sigma0
    w = apply_compliance(pressure, M)
    gap = G * hs
    degenerate = int(np.sum((np.abs(P) < 1e-9 * max(1.0, P.max())) & (np.abs(G) < 1e-9)))
    return DenseResult(
        pressure=pressure,
        displacement=w,
        gap=gap,
        rigid_position=float(delta * hs),
        mean_gap=float(gap.mean()),
        area=float(np.count_nonzero(pressure > 0) / pressure.size),
        mu=mu_dissipation(w, L, modulus, nu, velocity, sigma0),
        mu_literal=mu_dissipation(w, L, modulus, nu, velocity, sigma0, literal=True),
        mu_geometric=mu_geometric(pressure, h, L, sigma0),
        iterations=its,
        complementarity=float(np.max(np.abs(P * G))),
        min_pressure=float(P.min()),
        min_gap=float(G.min()),
        load_error=float(abs(P.mean() - 1.0)),
        n_degenerate=degenerate,
        history=history,
    )


def dense_solve(h, L, modulus, velocity, sigma0, nu=None, method="kernel"):
    """Exact discrete solution for an N x N height field h (m), N <= 48 (N^2 <= 2304 unknowns).

    ``modulus``: callable E(omega) -> complex (Pa), E'' > 0 for omega > 0; ``nu`` defaults to
    ``modulus.nu``. Returns a :class:`DenseResult`.
    """
    h = np.asarray(h, dtype=float)
    if h.ndim != 2 or h.shape[0] != h.shape[1]:
        raise ValueError("h must be N x N")
    if h.size > 2304:
        raise ValueError("dense reference limited to N <= 48")
    nu = modulus.nu if nu is None else nu
    M = multiplier(h.shape[0], L, modulus, nu, velocity)
    return _solve(h, L, modulus, nu, velocity, sigma0, M, method)


def dense_solve_1d(hx, L, modulus, velocity, sigma0, nu=None, method="kernel"):
    """Exact discrete solution for heights h(x) independent of y (1-D array of length N).

    The fields returned are 1-D (values along x); area, mean gap and mu are those of the 2-D
    N x N problem with h[i, j] = hx[i].
    """
    hx = np.asarray(hx, dtype=float)
    if hx.ndim != 1 or hx.size > 4096:
        raise ValueError("hx must be 1-D with N <= 4096")
    nu = modulus.nu if nu is None else nu
    M = multiplier_1d(hx.size, L, modulus, nu, velocity)
    return _solve(hx, L, modulus, nu, velocity, sigma0, M, method)


# ----------------------------------------------------------------------------- surfaces

def random_surface(N, L, psd, seed):
    """Random-phase, fixed-amplitude surface with |h_q|^2 = C(|q|) (2 pi / L)^2 (m).

    Independent of vecontact.core.surface (different random stream): used only to feed both the
    reference and the solver with the same heights.
    """
    rng = np.random.default_rng(seed)
    qx, qy = wavevectors(N, L)
    qabs = np.hypot(qx, qy)
    amp = np.sqrt(np.asarray(psd(qabs), dtype=float)) * (2.0 * np.pi / L)
    amp.flat[0] = 0.0
    # unit-modulus Hermitian random phases: FFT of real white noise, normalised
    u = np.fft.fft2(rng.standard_normal((N, N)))
    u /= np.abs(u)
    return np.fft.ifft2(amp * u).real * (N * N)
