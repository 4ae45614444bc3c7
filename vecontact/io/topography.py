"""Instrument topography files (x3p, sur, datx, opd, plu, Gwyddion, Digital Instruments, ...).

The files are read by SurfaceTopography (https://github.com/ComputationalMechanics/SurfaceTopography),
an optional extra: ``pip install 'vecontact[topography]'``. ``.npy`` and ``.h5`` height files are
not instrument files: vecontact reads them itself, as they are (:func:`vecontact.core.surface.load`).

What a measured scan becomes before the solver sees it (docs/inputs.md, "Instrument topography
files"), in this order:

1. the height channel is read (the file's default channel, or the one named by ``channel``), with
   lateral sizes and heights converted to m from the units the file states;
2. the pixels must be square (dx = dy to 0.1 %): the solver's grid is;
3. a non-square scan is cropped to its central n x n square, n = min(nx, ny) rounded down to an
   even number (cropping keeps only measured heights; padding would invent a flat region that
   carries load);
4. tilt and mean are removed: the least-squares plane over the cropped square is subtracted;
5. edges: a scan the file marks periodic is used as it is (period n dx). Any other scan is
   made periodic by reflection: [[h, h(:, ::-1)], [h(::-1, :), h(::-1, ::-1)]], a 2n x 2n surface
   of period 2 n dx whose heights are continuous across every edge (a periodic repeat of the raw scan
   would put a step at the edges, and a window would flatten the heights near them, which then
   carry no load). The reflection keeps every measured height; it costs a grid twice as wide.

Scans with undefined (missing) points are refused: fill them first. Results are cached per (file,
size, modification time, channel), so every rank and every use reads a file once.
"""
import os

import numpy as np

from vecontact.errors import InputError

__all__ = ["NATIVE_EXTENSIONS", "is_instrument_file", "read_topography", "EXTRA"]

#: Extensions vecontact reads itself (raw heights in m on the periodic grid).
NATIVE_EXTENSIONS = (".npy", ".h5", ".hdf5", ".he5")
#: The pip extra that brings SurfaceTopography.
EXTRA = "topography"
#: Largest relative difference of the pixel sizes dx, dy.
PIXEL_RTOL = 1e-3
#: Fewest points per side of the cropped scan.
MIN_POINTS = 16

_cache = {}


def is_instrument_file(path):
    """True unless ``path`` is a .npy or HDF5 height file."""
    return not os.fspath(path).lower().endswith(NATIVE_EXTENSIONS)


def _surface_topography(path, key):
    try:
        import SurfaceTopography
    except ImportError:
        raise InputError(key, f"{os.path.basename(path)} is an instrument file: reading it needs "
                              f"SurfaceTopography, pip install 'vecontact[{EXTRA}]'") from None
    return SurfaceTopography


def read_topography(path, channel=None, key="surface.file"):
    """Read and prepare an instrument scan: returns (heights, length, info).

    heights: (N, N) float64 array in m, axis 0 = x (the sliding direction), zero mean, no tilt,
    periodic; length: the period L = N dx in m; info: dict of what was read and done (format,
    channel, source grid and size, pixel size, crop, edges), for provenance.
    """
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError:
        raise InputError(key, f"file not found: {path}") from None
    tag = (os.path.abspath(path), st.st_size, st.st_mtime_ns, channel)
    if tag not in _cache:
        _cache.clear()          # one scan at a time: they can be large
        _cache[tag] = _read(path, channel, key)
    h, L, info = _cache[tag]
    return h.copy(), L, dict(info)


def _read(path, channel, key):
    ST = _surface_topography(path, key)
    name = os.path.basename(path)
    try:
        with ST.open_topography(path) as reader:
            chan = _channel(reader, channel, name, key)
            fmt = reader.name()
            if chan.dim != 2:
                raise InputError(key, f"{name}: channel {chan.name!r} is a {chan.dim}-D scan; the solver needs "
                                      f"a 2-D topography (a line scan's PSD can be used with spectrum: psd, "
                                      f"dimension: 1)")
            if chan.physical_sizes is None:
                raise InputError(key, f"{name}: the file states no physical size of the scan")
            topo = reader.topography(channel_index=chan.index)
    except InputError:
        raise
    except Exception as exc:   # SurfaceTopography's format detection and parsing errors
        if type(exc).__name__ == "CannotDetectFileFormat":   # its message lists every reader tried
            raise InputError(key, f"{name}: not a topography format SurfaceTopography knows (or a "
                                  f"damaged file)") from None
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise InputError(key, f"{name}: SurfaceTopography cannot read it ({type(exc).__name__}"
                              f"{': ' + text if text else ''})") from None
    if topo.has_undefined_data:
        raise InputError(key, f"{name}: the scan has undefined (missing) points; fill them first "
                              f"(e.g. SurfaceTopography's interpolate_undefined_data) and save it again")
    topo = topo.to_unit("m")
    h = np.array(topo.heights(), dtype=float)
    if not np.isfinite(h).all():
        raise InputError(key, f"{name}: non-finite heights")
    (nx, ny), (sx, sy) = h.shape, (float(topo.physical_sizes[0]), float(topo.physical_sizes[1]))
    dx, dy = sx / nx, sy / ny
    if abs(dx - dy) > PIXEL_RTOL * max(dx, dy):
        raise InputError(key, f"{name}: pixels are not square (dx = {dx:.4g} m, dy = {dy:.4g} m); "
                              f"resample the scan to square pixels first")
    n = min(nx, ny) // 2 * 2
    if n < MIN_POINTS:
        raise InputError(key, f"{name}: {nx} x {ny} points; need at least {MIN_POINTS} on each side")
    i0, j0 = (nx - n) // 2, (ny - n) // 2
    h = h[i0:i0 + n, j0:j0 + n]
    h = h - _plane(h)
    periodic = bool(topo.is_periodic)
    if not periodic:
        h = np.block([[h, h[:, ::-1]], [h[::-1, :], h[::-1, ::-1]]])
    L = h.shape[0] * dx
    steps = ["units -> m", f"cropped {nx} x {ny} -> central {n} x {n}" if (nx, ny) != (n, n) else
             f"{n} x {n}", "tilt and mean removed",
             "periodic as read" if periodic else f"reflected to {2 * n} x {2 * n} (non-periodic scan)"]
    info = {"format": fmt, "channel": chan.name, "source_grid": [int(nx), int(ny)],
            "source_size": [sx, sy], "pixel": dx, "crop": [int(i0), int(j0), int(n)],
            "periodic_in_file": periodic, "processing": "; ".join(steps)}
    return np.ascontiguousarray(h), float(L), info


def _channel(reader, channel, name, key):
    heights = [c for c in reader.channels if c.is_height_channel]
    if channel is None:
        chan = reader.default_channel
        if not chan.is_height_channel:
            raise InputError(key, f"{name}: the default channel {chan.name!r} holds no heights; name one of "
                                  f"{', '.join(repr(c.name) for c in heights) or '(none)'} with surface.dataset")
        return chan
    for c in heights:
        if channel in (c.name, c.channel_id):
            return c
    raise InputError(key.rsplit(".", 1)[0] + ".dataset",
                     f"{name} has no height channel {channel!r} (it has "
                     f"{', '.join(repr(c.name) for c in heights) or 'none'})")


def _plane(h):
    """The least-squares plane a + b x + c y through h on its grid (the regressors are orthogonal
    on a full grid once centred, so each coefficient is a projection)."""
    n0, n1 = h.shape
    x = np.arange(n0) - 0.5 * (n0 - 1)
    y = np.arange(n1) - 0.5 * (n1 - 1)
    b = (x @ h).sum() / (n1 * (x @ x))
    c = (h @ y).sum() / (n0 * (y @ y))
    return h.mean() + b * x[:, None] + c * y[None, :]
