"""Contact-morphology statistics of a periodic contact map: patches, their size, perimeter, anisotropy.

Conventions (docs/conventions.md §1): the map is an N x M grid of spacing dx (m, the same along both
axes) covering a periodic cell; axis 0 is x, the sliding direction (the rubber moves along +x), axis 1
is y. A pixel is one grid point of area dx^2.

Choices:

* Patches are the **4-connected** components of the contact set **on the torus** (4-connectivity is
  the usual choice in the rough-contact literature): pixels sharing an edge belong to the same patch,
  diagonal neighbours do not, and pixels that face each other across the periodic edges (row N-1
  and row 0, column M-1 and column 0) are neighbours too.
  ``scipy.ndimage.label`` labels the pieces inside the cell; pieces touching across the edges are
  merged with ``scipy.sparse.csgraph.connected_components``.
* A patch is **percolating** when it connects to one of its own periodic images (it wraps around the
  cell along x, y or a diagonal). Such a patch has no well-defined extent or moments: it counts in
  ``patches``, the area and the perimeter, but is left out of both anisotropy measures.
* Moments are taken in **unwrapped** coordinates: every piece gets a lattice offset (a multiple of N
  along x, of M along y) from a traversal of the merge graph, so that a patch crossing an edge is
  measured as one compact set. A cycle of that graph whose offsets do not close is a percolating patch.
"""
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import csgraph

__all__ = ["Morphology", "contact_morphology"]

#: 4-connectivity (the cross): ndimage.label's default in 2-D, spelled out because it is the contract.
_FOUR = ndimage.generate_binary_structure(2, 1)


@dataclass(frozen=True)
class Morphology:
    """Morphology of a periodic contact map (see :func:`contact_morphology` for the conventions).

    Attributes
    ----------
    patches : int
        Number of 4-connected contact patches on the torus, percolating ones included.
    percolating : int
        Number of patches that connect to one of their own periodic images (wrap around the cell).
    area_fraction : float
        Contact area / nominal area (dimensionless).
    mean_patch_area : float
        Total contact area / ``patches``, in m^2; NaN when there is no patch.
    perimeter : float
        Total length of the contact boundary, in m: the number of (contact, non-contact) pairs of
        4-neighbour pixels on the periodic grid, times dx.
    anisotropy_extent : float
        Mean extent along x / mean extent along y of the non-percolating patches (dimensionless),
        where a patch's extent along x is the number of distinct x indices it occupies times dx
        (and likewise along y); NaN when no non-percolating patch exists. Above 1: patches elongated
        along the sliding direction.
    anisotropy_moments : float
        sqrt(sum I_xx / sum I_yy) over the non-percolating patches (dimensionless), with I_xx, I_yy
        a patch's second central moments of its pixel centres in unwrapped coordinates plus dx^2/12
        per pixel (the pixel's own moment, so that a one-pixel patch is isotropic and an a x b
        rectangle gives exactly a / b); NaN when no non-percolating patch exists.
    """

    patches: int
    percolating: int
    area_fraction: float
    mean_patch_area: float
    perimeter: float
    anisotropy_extent: float
    anisotropy_moments: float


def contact_morphology(contact, spacing):
    """Morphology statistics of a periodic contact map.

    Parameters
    ----------
    contact : array_like, shape (N, M), bool (or 0/1 integers or floats)
        True where the surfaces touch. Axis 0 is x (the sliding direction), axis 1 is y; the map
        is periodic along both axes.
    spacing : float
        Grid spacing dx in m (the same along both axes).

    Returns
    -------
    Morphology
        Patches are 4-connected and joined across the periodic edges; percolating patches are
        counted but left out of both anisotropy measures (see :class:`Morphology`).

    Raises
    ------
    ValueError
        If ``contact`` is not a non-empty 2-D array of 0/1 values, or ``spacing`` is not a positive
        finite number.
    """
    c, dx = _check(contact, spacing)
    N, M = c.shape
    # Each (contact, non-contact) edge is met once when every pixel is compared with its periodic
    # predecessor along each axis.
    edges = int(np.count_nonzero(c != np.roll(c, 1, axis=0)) + np.count_nonzero(c != np.roll(c, 1, axis=1)))
    labels, pieces = ndimage.label(c, structure=_FOUR)
    if pieces == 0:
        return Morphology(0, 0, 0.0, math.nan, edges * dx, math.nan, math.nan)

    patch, wraps, offset = _merge(_wrap_links(labels), pieces)
    flat = np.flatnonzero(c)
    piece = labels.ravel()[flat] - 1
    owner = patch[piece]
    count = np.bincount(owner)
    ext_x, mom_x = _axis_stats(flat // M + N * offset[piece, 0], owner, count, N)
    ext_y, mom_y = _axis_stats(flat % M + M * offset[piece, 1], owner, count, M)

    keep = ~wraps
    if keep.any():
        aniso_extent = ext_x[keep].sum() / ext_y[keep].sum()
        aniso_moments = math.sqrt(mom_x[keep].sum() / mom_y[keep].sum())
    else:
        aniso_extent = aniso_moments = math.nan
    return Morphology(
        patches=int(count.size),
        percolating=int(wraps.sum()),
        area_fraction=flat.size / (N * M),
        mean_patch_area=flat.size * dx * dx / count.size,
        perimeter=edges * dx,
        anisotropy_extent=float(aniso_extent),
        anisotropy_moments=aniso_moments,
    )


def _check(contact, spacing):
    """The map as a bool array and the spacing as a float, or ValueError."""
    c = np.asarray(contact)
    if c.ndim != 2 or c.size == 0:
        raise ValueError(f"contact must be a non-empty 2-D array (N, M), got shape {c.shape}")
    if c.dtype != bool:
        numeric = np.issubdtype(c.dtype, np.integer) or np.issubdtype(c.dtype, np.floating)
        if not numeric or not np.all((c == 0) | (c == 1)):
            raise ValueError(f"contact must be boolean or hold only 0 and 1, got dtype {c.dtype}")
        c = c != 0
    try:
        dx = float(spacing)
    except (TypeError, ValueError):
        dx = math.nan
    if not (math.isfinite(dx) and dx > 0):
        raise ValueError(f"spacing must be a positive finite length in m, got {spacing!r}")
    return c, dx


def _wrap_links(labels):
    """Distinct links (a, b, sx, sy) between pieces touching across the periodic edges.

    Pieces are numbered from 0 (label - 1). Piece b continues piece a when b is translated by
    (sx N, sy M): row 0 continues row N-1 (step (1, 0)), column 0 continues column M-1 (step (0, 1)).
    """
    N, M = labels.shape
    a = np.concatenate([labels[-1, :], labels[:, -1]])
    b = np.concatenate([labels[0, :], labels[:, 0]])
    sx = np.repeat([1, 0], [M, N])
    touch = (a > 0) & (b > 0)
    links = np.stack([a - 1, b - 1, sx, 1 - sx], axis=1)[touch]
    return np.unique(links, axis=0)


def _merge(links, pieces):
    """Patch of each piece, the wrap flag of each patch and the lattice offset (ox, oy) of each piece.

    The offsets come from a depth-first traversal of the link graph (O(N + M) links at most, so a
    Python loop is cheap); a link whose offsets disagree closes a cycle that winds around the cell:
    its patch percolates (a self-link, e.g. a column of full height, is such a cycle).
    """
    graph = sparse.coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(pieces, pieces))
    _, patch = csgraph.connected_components(graph, directed=False)
    adjacent = {}
    for a, b, sx, sy in links.tolist():
        adjacent.setdefault(a, []).append((b, sx, sy))
        adjacent.setdefault(b, []).append((a, -sx, -sy))
    where = {}
    wrapping = set()
    for root in adjacent:
        if root in where:
            continue
        where[root] = (0, 0)
        stack = [root]
        while stack:
            u = stack.pop()
            ux, uy = where[u]
            for v, sx, sy in adjacent[u]:
                w = (ux + sx, uy + sy)
                if v not in where:
                    where[v] = w
                    stack.append(v)
                elif where[v] != w:
                    wrapping.add(root)
    offset = np.zeros((pieces, 2), dtype=np.int64)
    if where:
        offset[list(where)] = list(where.values())
    wraps = np.zeros(patch.max() + 1, dtype=bool)
    wraps[patch[list(wrapping)]] = True
    return patch, wraps, offset


def _axis_stats(u, owner, count, period):
    """Extent (grid lines) and second central moment (pixel^2, + 1/12 per pixel) of each patch.

    u: unwrapped index of each contact pixel along the axis; owner: its patch; count: pixels per
    patch; period: N or M. A non-percolating patch is 4-connected in unwrapped coordinates, so its
    indices form one run: the distinct indices modulo the period are min(period, run length).
    """
    npatch = count.size
    lo = np.full(npatch, np.iinfo(np.int64).max)
    hi = np.full(npatch, np.iinfo(np.int64).min)
    np.minimum.at(lo, owner, u)
    np.maximum.at(hi, owner, u)
    extent = np.minimum(hi - lo + 1, period)
    # Two passes (mean, then squared deviations): no cancellation between large sums.
    mean = np.bincount(owner, u, npatch) / count
    moment = np.bincount(owner, (u - mean[owner]) ** 2, npatch) + count / 12.0
    return extent, moment
