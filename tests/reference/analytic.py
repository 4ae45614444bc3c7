"""Closed-form contact results used as references (docs/conventions.md §6).

All functions are pure numpy/math; E* = E / (1 - nu^2).
"""
import math

import numpy as np

__all__ = ["westergaard_pstar", "westergaard_area", "westergaard_pmax", "westergaard_mean_gap",
           "westergaard_pressure", "jgh_pstar", "jgh_area_low", "jgh_area_high",
           "full_contact_pressure", "full_contact_mu", "cosine_mu", "cosine_phase"]


# ------------------------------------------------------------------ Westergaard (1-D sinusoid)

def westergaard_pstar(E, nu, D, wavelength):
    """Full-contact pressure p* = pi E D / ((1 - nu^2) lambda) for h = D cos(2 pi x / lambda)."""
    return math.pi * E * D / ((1.0 - nu ** 2) * wavelength)


def westergaard_area(r):
    """A/A0 = (2/pi) arcsin(sqrt(r)), r = pbar / p* (<= 1)."""
    return 2.0 / math.pi * math.asin(math.sqrt(min(r, 1.0)))


def westergaard_pmax(pbar, pstar):
    """Peak pressure 2 sqrt(pbar p*) (partial contact)."""
    return 2.0 * math.sqrt(pbar * pstar)


def westergaard_mean_gap(D, r):
    """Mean gap D (1 - r + r ln r) (partial contact, r = pbar / p*)."""
    return D * (1.0 - r + r * math.log(r))


def westergaard_pressure(x, wavelength, pbar, pstar):
    """Continuous pressure p(x) for contact centred on the crest x = 0 (x any array)."""
    s2 = pbar / pstar
    a = wavelength / math.pi * math.asin(math.sqrt(s2))
    xm = (np.asarray(x) + wavelength / 2) % wavelength - wavelength / 2
    inside = np.abs(xm) < a
    arg = np.clip(s2 - np.sin(math.pi * xm / wavelength) ** 2, 0.0, None)
    return np.where(inside, 2.0 * pbar / s2 * np.cos(math.pi * xm / wavelength) * np.sqrt(arg), 0.0)


# ------------------------------------------------ 2-D sinusoid (Johnson, Greenwood & Higginson)

def jgh_pstar(E, nu, D, wavelength):
    """Full-contact pressure p* = sqrt(2) pi E* D / lambda for h = D cos(kx) cos(ky)."""
    return math.sqrt(2.0) * math.pi * E * D / ((1.0 - nu ** 2) * wavelength)


def jgh_area_low(r):
    """Low-load (Hertz) asymptote A/A0 = 0.7616 (pbar/p*)^(2/3).

    Exact coefficient: two Hertzian asperities of radius R = 1/(D k^2) per cell lambda^2, each
    carrying pbar lambda^2 / 2: A/A0 = 2 pi (3 sqrt(2) / (32 pi))^(2/3) r^(2/3) = 0.76165 r^(2/3).
    """
    coef = 2.0 * math.pi * (3.0 * math.sqrt(2.0) / (32.0 * math.pi)) ** (2.0 / 3.0)
    return coef * r ** (2.0 / 3.0)


def jgh_area_high(r):
    """Near-full-contact asymptote A/A0 = 1 - (3 / (2 pi)) (1 - pbar/p*)."""
    return 1.0 - 3.0 / (2.0 * math.pi) * (1.0 - r)


# ----------------------------------------------------------------------- full contact

def _grid_q(N, L):
    q = 2.0 * math.pi * np.fft.fftfreq(N, d=L / N)
    qx, qy = np.meshgrid(q, q, indexing="ij")
    return qx, qy


def full_contact_pressure(h, L, modulus, nu, velocity, sigma0):
    """p = sigma0 + M (h - mean h) for full contact (w = h + const); x-Nyquist row real."""
    h = np.asarray(h, dtype=float)
    N = h.shape[0]
    qx, qy = _grid_q(N, L)
    M = np.hypot(qx, qy) * np.asarray(modulus(qx * velocity), dtype=complex) / (2.0 * (1.0 - nu ** 2))
    if N % 2 == 0:
        M[N // 2, :] = M[N // 2, :].real
    M[0, 0] = 0.0
    return sigma0 + np.fft.ifft2(M * np.fft.fft2(h)).real


def full_contact_mu(h, L, modulus, nu, velocity, sigma0):
    """mu = sum_{q != 0} |q| q_x E''(q_x v) |h_q|^2 / (2 (1 - nu^2) sigma0) (section 4, w = h)."""
    h = np.asarray(h, dtype=float)
    N = h.shape[0]
    qx, qy = _grid_q(N, L)
    hq = np.fft.fft2(h) / N ** 2
    Epp = np.asarray(modulus(qx * velocity), dtype=complex).imag
    terms = np.hypot(qx, qy) * qx * Epp * np.abs(hq) ** 2 / (2.0 * (1.0 - nu ** 2) * sigma0)
    terms[0, 0] = 0.0
    return float(terms.sum())


def cosine_mu(k, h0, modulus, nu, velocity, sigma0):
    """mu = k^2 h0^2 E''(k v) / (4 (1 - nu^2) sigma0) for h = h0 cos(k x) in full contact."""
    Epp = complex(np.asarray(modulus(np.array([k * velocity])))[0]).imag
    return k ** 2 * h0 ** 2 * Epp / (4.0 * (1.0 - nu ** 2) * sigma0)


def cosine_phase(k, modulus, velocity):
    """Loss angle delta = arg E(k v): p = sigma0 + |M_k| h0 cos(k x + delta) in full contact."""
    E = complex(np.asarray(modulus(np.array([k * velocity])))[0])
    return math.atan2(E.imag, E.real)
