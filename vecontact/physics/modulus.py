"""Linear viscoelastic moduli E(omega) of the rubber (docs/conventions.md §3).

Every model is a callable ``model(omega) -> complex ndarray`` with

* ``omega`` the angular frequency in rad/s, any sign, any array shape (scalars allowed);
* E(omega) = E'(omega) + i E''(omega) in Pa, with E'' >= 0 for omega > 0 (DMA convention)
  and E(-omega) = conj(E(omega)), so E(0) is real;
* attributes ``E0`` = E(0) (relaxed, rubbery modulus, Pa), ``Einf`` = E(infinity) (glassy
  modulus, Pa) and ``nu`` (Poisson ratio), and ``describe()`` giving a one-line summary.

Models: :class:`Elastic`, :class:`SLS`, :class:`Prony` (generalised Maxwell),
:class:`HavriliakNegami`, :class:`Table` (tabulated master curve with optional WLF shift).
:func:`make_modulus` builds one from the ``material`` section of a job file (a job's
:meth:`vecontact.jobtypes.Material.modulus` builds it once and keeps it).
"""
import math
import os
import warnings

import numpy as np

from vecontact.errors import InputError, InputWarning
from vecontact.io.tables import read_columns

__all__ = ["Elastic", "SLS", "Prony", "HavriliakNegami", "Table", "make_modulus", "wlf_shift",
           "coverage", "warn_coverage"]

#: Frequency units of a master-curve table: factor to angular frequency (rad/s).
FREQUENCY_UNITS = {"rad/s": 1.0, "Hz": 2.0 * math.pi}
#: Modulus units of a master-curve table: factor to Pa.
MODULUS_UNITS = {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9}
#: Storage moduli (Pa) a solid's master curve can have; outside, the table's unit is wrong.
PLAUSIBLE_STORAGE = (1e3, 1e12)


class _Modulus:
    """Base class: evaluates the model at |omega| and applies E(-w) = conj E(w)."""

    E0 = None
    Einf = None
    nu = 0.5

    def __call__(self, omega):
        omega = np.asarray(omega, dtype=float)
        value = np.asarray(self._positive(np.abs(omega)), dtype=complex)
        return np.where(omega < 0, np.conj(value), value)

    def _positive(self, omega):
        """E at omega >= 0 (float ndarray) -> complex ndarray; implemented by the models."""
        raise NotImplementedError

    def describe(self):
        raise NotImplementedError


class Elastic(_Modulus):
    """Frequency-independent elastic solid: E(omega) = E (Pa) for all omega."""

    def __init__(self, E, nu=0.5):
        self.E0 = self.Einf = float(E)
        self.nu = float(nu)

    def _positive(self, omega):
        return np.full(omega.shape, self.E0, dtype=complex)

    def describe(self):
        return f"elastic: E = {self.E0:.4g} Pa, nu = {self.nu:g}"


class Prony(_Modulus):
    """Generalised Maxwell model (Prony series).

    E(omega) = E0 + sum_k dE_k i omega t_k / (1 + i omega t_k), with ``terms = [[dE_k, t_k], ...]``
    (dE_k in Pa, t_k in s, both > 0). E(0) = E0 and Einf = E0 + sum_k dE_k.
    """

    def __init__(self, E0, terms, nu=0.5):
        terms = np.asarray(terms, dtype=float).reshape(-1, 2)
        self.E0 = float(E0)
        self.dE = terms[:, 0].copy()
        self.tau = terms[:, 1].copy()
        self.Einf = self.E0 + float(self.dE.sum())
        self.nu = float(nu)

    def _positive(self, omega):
        iwt = 1j * omega[..., None] * self.tau
        return self.E0 + np.sum(self.dE * iwt / (1.0 + iwt), axis=-1)

    def describe(self):
        return (f"prony: E0 = {self.E0:.4g} Pa, Einf = {self.Einf:.4g} Pa, "
                f"{len(self.tau)} terms, tau {self.tau.min():.3g}..{self.tau.max():.3g} s, "
                f"nu = {self.nu:g}")


class SLS(Prony):
    """Standard linear solid (Zener): one Prony term with dE = Einf - E0 and relaxation time tau (s)."""

    def __init__(self, E0, Einf, tau, nu=0.5):
        super().__init__(E0, [[float(Einf) - float(E0), tau]], nu)

    def describe(self):
        return (f"sls: E0 = {self.E0:.4g} Pa, Einf = {self.Einf:.4g} Pa, tau = {self.tau[0]:.4g} s, "
                f"nu = {self.nu:g}")


class HavriliakNegami(_Modulus):
    """Havriliak-Negami modulus E(omega) = Einf + (E0 - Einf) / (1 + (i omega tau)^alpha)^beta.

    Evaluated for omega >= 0 with (i omega tau)^alpha = (omega tau)^alpha exp(i pi alpha / 2)
    (principal branch; 1 + (i omega tau)^alpha has a positive real part for 0 < alpha <= 1, so the
    outer power is unambiguous), and by conjugation for omega < 0. E0, Einf in Pa, tau in s.
    """

    def __init__(self, E0, Einf, alpha, beta, tau, nu=0.5):
        self.E0 = float(E0)
        self.Einf = float(Einf)
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.tau = float(tau)
        self.nu = float(nu)

    def _positive(self, omega):
        z = (omega * self.tau) ** self.alpha * np.exp(0.5j * math.pi * self.alpha)
        # E = E0 + (Einf - E0) (1 - (1 + z)^-beta), with 1 - (1 + z)^-beta = -expm1(-beta log1p(z))
        # evaluated without cancellation, so E - E0 (and E'' >= 0) stay accurate as omega -> 0.
        relaxed_fraction = -_expm1_complex(-self.beta * _log1p_complex(z))
        return self.E0 + (self.Einf - self.E0) * relaxed_fraction

    def describe(self):
        return (f"havriliak-negami: E0 = {self.E0:.4g} Pa, Einf = {self.Einf:.4g} Pa, "
                f"alpha = {self.alpha:g}, beta = {self.beta:g}, tau = {self.tau:.4g} s, nu = {self.nu:g}")


def _log1p_complex(z):
    """log(1 + z) for complex z with Re z >= 0, accurate for small |z|."""
    x, y = z.real, z.imag
    return 0.5 * np.log1p(x * (2.0 + x) + y * y) + 1j * np.arctan2(y, 1.0 + x)


def _expm1_complex(u):
    """exp(u) - 1 for complex u, accurate for small |u|."""
    a, b = u.real, u.imag
    half_sin = np.sin(0.5 * b)
    real = np.expm1(a) * np.cos(b) - 2.0 * half_sin * half_sin
    return real + 1j * np.exp(a) * np.sin(b)


def wlf_shift(wlf):
    """WLF shift factor aT: log10 aT = -C1 (T - T_ref) / (C2 + T - T_ref); 1 if ``wlf`` is None.

    ``wlf`` is a dict with keys C1, C2 (K), T_ref, T (same temperature unit, e.g. degC or K).
    """
    if not wlf:
        return 1.0
    dT = float(wlf["T"]) - float(wlf["T_ref"])
    return 10.0 ** (-float(wlf["C1"]) * dT / (float(wlf["C2"]) + dT))


class Table(_Modulus):
    """Tabulated master curve (omega_k, E'_k, E''_k) at the reference temperature, optional WLF shift.

    * Inside [omega_min, omega_max]: E' and E'' are interpolated linearly in (log omega, log E).
    * Outside: E' is extrapolated as a constant, E'(omega_min) below and E'(omega_max) above, so
      E0 = E'(omega_min) and Einf = E'(omega_max). E'' cannot be held constant (it must vanish at
      omega = 0 and at infinity for E(-w) = conj E(w) to make E(0) = E0 real, and for the friction
      to vanish in the elastic limits), so it is continued as a terminal (Maxwell-like) tail:
      E''(omega_min) omega / omega_min below and E''(omega_max) omega_max / omega above.
    * ``wlf`` (dict C1, C2, T_ref, T): E(omega, T) = E(aT omega, T_ref) with aT from
      :func:`wlf_shift`. E0 and Einf are unchanged by the shift.
    * ``vertical_shift`` bT > 0 (dimensionless, default 1): E(omega, T) = bT E(aT omega, T_ref), the
      vertical (modulus) shift of time-temperature superposition, often T rho / (T_ref rho_ref);
      it scales E0 and Einf too.
    """

    def __init__(self, omega, E_storage, E_loss, nu=0.5, wlf=None, vertical_shift=1.0):
        self.omega = np.asarray(omega, dtype=float)
        self.E_storage = np.asarray(E_storage, dtype=float)
        self.E_loss = np.asarray(E_loss, dtype=float)
        problem = _table_problem(self.omega, self.E_storage, self.E_loss)
        if problem:
            raise ValueError(problem)
        self.nu = float(nu)
        self.wlf = dict(wlf) if wlf else None
        self.aT = wlf_shift(self.wlf)
        self.bT = float(vertical_shift)
        if not (self.bT > 0 and math.isfinite(self.bT)):
            raise ValueError(f"vertical_shift must be a positive number, got {vertical_shift!r}")
        self.E0 = self.bT * float(self.E_storage[0])
        self.Einf = self.bT * float(self.E_storage[-1])
        self._log_omega = np.log(self.omega)
        self._log_storage = np.log(self.E_storage)
        self._log_loss = np.log(self.E_loss)
        self.source = None

    @classmethod
    def from_file(cls, path, nu=0.5, wlf=None, *, frequency_unit="rad/s", modulus_unit="Pa",
                  columns=None, vertical_shift=1.0):
        """Read a master curve from a text or CSV table: frequency, E', E'' (one row per frequency).

        The table format is that of :func:`vecontact.io.tables.read_columns` (comma, semicolon, tab
        or space separated; '#' comments; an optional header line). ``columns``: None (exactly three
        columns: frequency, E', E'') or three 0-based indices or header names picking them from a
        wider DMA export. ``frequency_unit``: "rad/s" (angular frequency omega) or "Hz" (f, with
        omega = 2 pi f); ``modulus_unit``: Pa, kPa, MPa or GPa. ``wlf``, ``vertical_shift``: see
        the class. Raises ``InputError("material.file", ...)`` for an unreadable file, a malformed
        line, fewer than two rows, non-positive values, frequencies not strictly increasing, or
        storage moduli outside 1 kPa .. 1 TPa after the unit conversion (a unit mistake).
        """
        if frequency_unit not in FREQUENCY_UNITS:
            raise InputError("material.frequency_unit", f"must be one of {', '.join(FREQUENCY_UNITS)}, "
                                                        f"got {frequency_unit!r}")
        if modulus_unit not in MODULUS_UNITS:
            raise InputError("material.modulus_unit", f"must be one of {', '.join(MODULUS_UNITS)}, "
                                                      f"got {modulus_unit!r}")
        data = read_columns(path, "material.file", ("frequency", "E'", "E''"), columns)
        omega = data[:, 0] * FREQUENCY_UNITS[frequency_unit]
        storage = data[:, 1] * MODULUS_UNITS[modulus_unit]
        loss = data[:, 2] * MODULUS_UNITS[modulus_unit]
        problem = _table_problem(omega, storage, loss)
        if problem:
            raise InputError("material.file", f"{path}: {problem}")
        lo, hi = PLAUSIBLE_STORAGE
        if storage.min() < lo or storage.max() > hi:
            raise InputError("material.file", f"{path}: E' = {storage.min():.3g} .. {storage.max():.3g} Pa is "
                                              f"not a solid's modulus ({lo:g} .. {hi:g} Pa): set "
                                              f"material.modulus_unit ({', '.join(MODULUS_UNITS)})")
        table = cls(omega, storage, loss, nu=nu, wlf=wlf, vertical_shift=vertical_shift)
        table.source = os.fspath(path)
        return table

    def _positive(self, omega):
        w = omega * self.aT
        w_min, w_max = self.omega[0], self.omega[-1]
        log_w = np.log(np.clip(w, w_min, w_max))
        storage = np.exp(np.interp(log_w, self._log_omega, self._log_storage))
        storage = np.where(w <= w_min, self.E_storage[0], np.where(w >= w_max, self.E_storage[-1], storage))
        loss = np.exp(np.interp(log_w, self._log_omega, self._log_loss))
        tail = np.where(w < w_min, w / w_min, w_max / np.maximum(w, w_max))   # 1 inside the table
        return self.bT * (storage + 1j * loss * tail)

    def describe(self):
        src = f" from {self.source}" if self.source else ""
        shift = f", WLF aT = {self.aT:.4g}" if self.wlf else ""
        shift += f", vertical shift bT = {self.bT:.4g}" if self.bT != 1.0 else ""
        return (f"table{src}: {len(self.omega)} points, "
                f"omega {self.omega[0]:.3g}..{self.omega[-1]:.3g} rad/s, "
                f"E0 = {self.E0:.4g} Pa, Einf = {self.Einf:.4g} Pa{shift}, nu = {self.nu:g}")


def _table_problem(omega, storage, loss):
    """Return a one-line description of what is wrong with a master-curve table, or None."""
    if omega.ndim != 1 or not (omega.shape == storage.shape == loss.shape):
        return "omega, E' and E'' must be 1-D arrays of equal length"
    if omega.size < 2:
        return "need at least two rows (omega, E', E'')"
    if not (np.all(np.isfinite(omega)) and np.all(np.isfinite(storage)) and np.all(np.isfinite(loss))):
        return "non-finite values"
    if np.any(omega <= 0) or np.any(storage <= 0) or np.any(loss <= 0):
        return "omega, E' and E'' must all be positive (log-log interpolation)"
    if np.any(np.diff(omega) <= 0):
        return "omega must be strictly increasing"
    return None


def make_modulus(material):
    """Build a modulus model from a (validated) job ``material`` dict.

    Keys: ``model`` in {elastic, sls, prony, havriliak-negami, table}; ``E0`` (Pa; the modulus of an
    elastic solid), ``Einf`` (Pa), ``alpha``, ``beta``, ``tau`` (s), ``terms`` ([[dE, tau], ...]),
    ``file`` (table path), ``wlf`` (dict, table only), ``frequency_unit``, ``modulus_unit``,
    ``columns``, ``vertical_shift`` (table only, see :meth:`Table.from_file`), ``nu`` (default 0.5).
    """
    model = str(material["model"]).lower()
    nu = material.get("nu", 0.5)
    if model == "elastic":
        return Elastic(material["E0"], nu)
    if model == "sls":
        return SLS(material["E0"], material["Einf"], material["tau"], nu)
    if model == "prony":
        return Prony(material["E0"], material["terms"], nu)
    if model in ("havriliak-negami", "havriliak_negami", "hn"):
        return HavriliakNegami(material["E0"], material["Einf"], material["alpha"], material["beta"],
                               material["tau"], nu)
    if model == "table":
        return Table.from_file(material["file"], nu, material.get("wlf"),
                               frequency_unit=material.get("frequency_unit", "rad/s"),
                               modulus_unit=material.get("modulus_unit", "Pa"),
                               columns=material.get("columns"),
                               vertical_shift=material.get("vertical_shift", 1.0))
    raise InputError("material.model", f"unknown model {material['model']!r}")


def coverage(modulus, q_min, q_max, velocities):
    """Where the frequencies a job needs leave a tabulated master curve: a one-line message, or None.

    The roughness wavevectors q in [q_min, q_max] (1/m) are felt at omega = q v cos(phi) <= q v
    (rad/s) for each sliding velocity v (m/s). Frequencies near 0 (phi -> pi/2) always fall below a
    table and are harmless (E -> E0 there); the message reports, per velocity, the wavevectors
    whose main frequency q v lies outside the table (after the WLF shift) and how E is extrapolated
    there. Analytic models cover every frequency: None.
    """
    if not isinstance(modulus, Table):
        return None
    lo, hi = modulus.omega[0] / modulus.aT, modulus.omega[-1] / modulus.aT
    parts = []
    for v in sorted(float(v) for v in np.atleast_1d(velocities)):
        if v <= 0:
            continue
        outside = []
        if q_min * v < lo:
            outside.append(f"q < {min(lo / v, q_max):.3g} 1/m below omega_min")
        if q_max * v > hi:
            outside.append(f"q > {max(hi / v, q_min):.3g} 1/m above omega_max")
        if outside:
            parts.append(f"v = {v:g} m/s: " + " and ".join(outside))
    if not parts:
        return None
    shift = f" at the job's temperature (WLF aT = {modulus.aT:.3g})" if modulus.wlf else ""
    return (f"the master curve covers omega = {lo:.3g} .. {hi:.3g} rad/s{shift}, the roughness "
            f"(q = {q_min:.3g} .. {q_max:.3g} 1/m) needs omega = q v: {'; '.join(parts)}. There E is "
            f"extrapolated: E' held at E'(omega_min) below and E'(omega_max) above, E'' falling as "
            f"omega / omega_min below and omega_max / omega above")


def warn_coverage(modulus, q_min, q_max, velocities, key="material.file", stacklevel=2):
    """Warn (:class:`InputWarning`, message under ``key``) when a tabulated modulus does not cover
    the frequencies q v of wavevectors q in [q_min, q_max] (1/m); see :func:`coverage`.
    ``stacklevel`` as for :func:`warnings.warn`, counted from the caller of this function."""
    text = coverage(modulus, q_min, q_max, velocities)
    if text:
        warnings.warn(f"{key}: {text}", InputWarning, stacklevel=stacklevel + 1)
