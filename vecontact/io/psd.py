"""Measured power spectra: a C(q) table from a file, checked, as a :class:`Tabulated` spectrum.

File: two columns, q (1/m) and the PSD (table format of :mod:`vecontact.io.tables`), either

* ``dimension=2`` (default): Persson's isotropic 2-D C(q) in m^4 (docs/conventions.md §2,
  h_rms^2 = 2 pi Int q C dq), or
* ``dimension=1``: a line-scan PSD C1D(q) in m^3 (two-sided, h_rms^2 = Int_{-inf}^{inf} C1D dq),
  converted to the 2-D C(q) by the Abel inversion of
  :func:`vecontact.physics.spectrum.isotropic_from_line` (docs/inputs.md, "1-D line-scan spectra").

Checks (each an :class:`InputError` under ``key``, one line naming the file): at least
``MIN_ROWS`` rows; q strictly increasing and positive; C positive (no negative, no zero rows);
units: q inside ``Q_RANGE`` (wavelengths 6 m .. 60 pm), h_rms inside ``HRMS_RANGE`` and the rms
slope below ``MAX_SLOPE`` -- a table in 1/mm, 1/um, um^4 or nm^4 fails one of them.
"""
import math
import os

import numpy as np

from vecontact.errors import InputError
from vecontact.io.tables import read_columns
from vecontact.physics.spectrum import Tabulated, isotropic_from_line

__all__ = ["read_psd", "MIN_ROWS", "Q_RANGE", "HRMS_RANGE", "MAX_SLOPE"]

#: Fewest rows of a measured spectrum.
MIN_ROWS = 8
#: Wavevectors (1/m) a roughness spectrum can hold: wavelengths 2 pi / q from 6.3 m to 63 pm.
Q_RANGE = (1.0, 1e11)
#: Root-mean-square heights (m) a measured surface can have: 1 pm .. 1 cm.
HRMS_RANGE = (1e-12, 1e-2)
#: Largest plausible rms slope <|grad h|^2>^1/2 (84 degrees).
MAX_SLOPE = 10.0

_cache = {}


def read_psd(path, dimension=2, key="surface.file", columns=None):
    """The 2-D spectrum (:class:`Tabulated`, q in 1/m, C in m^4) of the table in ``path``.

    ``dimension``: 2 (the file holds Persson's 2-D C(q), m^4) or 1 (a line-scan C1D(q), m^3,
    inverted to 2-D); ``columns``: None (exactly two columns q, C) or two column indices / header
    names. Results are cached per (file, size, modification time, options).
    """
    path = os.fspath(path)
    if dimension not in (1, 2):
        raise InputError(key.rsplit(".", 1)[0] + ".dimension", f"must be 1 or 2, got {dimension!r}")
    try:
        st = os.stat(path)
    except OSError:
        raise InputError(key, f"file not found: {path}") from None
    tag = (os.path.abspath(path), st.st_size, st.st_mtime_ns, dimension,
           None if columns is None else tuple(columns))
    if tag not in _cache:
        _cache[tag] = _read(path, dimension, key, columns)
    return _cache[tag]


def _read(path, dimension, key, columns):
    unit = "m^4" if dimension == 2 else "m^3"
    data = read_columns(path, key, ("q", "C"), columns)
    q, C = data[:, 0], data[:, 1]
    name = os.path.basename(path)
    if q.size < MIN_ROWS:
        raise InputError(key, f"{name}: {q.size} rows; a measured spectrum needs at least {MIN_ROWS}")
    if np.any(q <= 0):
        raise InputError(key, f"{name}: q must be > 0 (1/m), row {int(np.argmax(q <= 0)) + 1} has q = "
                              f"{q[q <= 0][0]:g}")
    steps = np.diff(q)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 2
        raise InputError(key, f"{name}: q must increase strictly, row {k} has q = {q[k - 1]:g} after "
                              f"{q[k - 2]:g}")
    if np.any(C < 0):
        k = int(np.argmax(C < 0))
        raise InputError(key, f"{name}: negative C = {C[k]:g} at q = {q[k]:g} 1/m (row {k + 1})")
    if np.any(C == 0):
        k = int(np.argmax(C == 0))
        raise InputError(key, f"{name}: C = 0 at q = {q[k]:g} 1/m (row {k + 1}); the spectrum is "
                              f"interpolated in log-log and needs C > 0: leave such rows out")
    lo, hi = Q_RANGE
    if q[0] < lo or q[-1] > hi:
        raise InputError(key, f"{name}: q = {q[0]:.3g} .. {q[-1]:.3g} is not a range of wavevectors in "
                              f"1/m (expected within {lo:g} .. {hi:g} 1/m): convert q to 1/m "
                              f"(q = 2 pi / wavelength)")
    if dimension == 1:
        try:
            C2 = isotropic_from_line(q, C)
        except ValueError as exc:
            raise InputError(key, f"{name}: {exc}") from None
        if np.any(C2 <= 0):
            k = int(np.argmax(C2 <= 0))
            raise InputError(key, f"{name}: the 2-D spectrum from this line-scan PSD is <= 0 at "
                                  f"q = {q[k]:.4g} 1/m (C1D must fall with q; smooth or trim the table)")
        C = C2
    psd = Tabulated(q, C)
    hrms, slope = psd.hrms(), math.sqrt(psd.slope2())
    lo, hi = HRMS_RANGE
    if not lo <= hrms <= hi or slope > MAX_SLOPE:
        raise InputError(key, f"{name}: h_rms = {hrms:.3g} m and rms slope {slope:.3g} are not those of a "
                              f"surface (h_rms {lo:g} .. {hi:g} m, slope < {MAX_SLOPE:g}): the units must "
                              f"be q in 1/m and C in {unit}"
                              + (" (Persson's 2-D convention)" if dimension == 2 else ""))
    return psd
