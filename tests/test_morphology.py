"""Contact-morphology statistics (vecontact.analysis.morphology) against known answers and brute force.

Tolerances: rtol = 1e-12 where two computations of the same quantity differ only by the order of
float64 sums over at most a few thousand terms of size <= 1e6 (relative rounding well below 1e-13);
integer counts are compared exactly; the ellipse tolerances are the digitisation error (see there).
"""
import math
from collections import deque

import numpy as np
import pytest
from scipy import ndimage

from vecontact.analysis.morphology import Morphology, contact_morphology

DX = 2.5e-7  # m, a typical grid spacing (L = 25 um on 100 points)
RTOL = 1e-12


def rectangle(shape, x0, y0, a, b):
    """An a x b block of contact (a along x = axis 0) with its corner at (x0, y0), wrapped."""
    c = np.zeros(shape, dtype=bool)
    c[np.ix_(np.arange(x0, x0 + a) % shape[0], np.arange(y0, y0 + b) % shape[1])] = True
    return c


def brute_force(c):
    """Independent reference: breadth-first flood fill on the torus with explicit modular neighbours.

    Each pixel is reached with an unwrapped position; reaching a pixel again at another position
    means the patch meets its own periodic image (percolating). Returns the patch and percolating
    counts, the boundary edge count and, summed over the non-percolating patches, the distinct-x and
    distinct-y counts and the second central moments (+ 1/12 per pixel), all in pixel units.
    """
    N, M = c.shape
    steps = ((1, 0), (-1, 0), (0, 1), (0, -1))
    position = {}
    out = dict(patches=0, percolating=0, edges=0, ext_x=0, ext_y=0, I_xx=0.0, I_yy=0.0)
    for i in range(N):
        for j in range(M):
            if not c[i, j]:
                continue
            out["edges"] += sum(not c[(i + di) % N, (j + dj) % M] for di, dj in steps)
            if (i, j) in position:
                continue
            out["patches"] += 1
            position[i, j] = (i, j)
            queue, points, wraps = deque([(i, j)]), [], False
            while queue:
                ui, uj = queue.popleft()
                points.append((ui, uj))
                for di, dj in steps:
                    vi, vj = ui + di, uj + dj
                    key = (vi % N, vj % M)
                    if not c[key]:
                        continue
                    if key not in position:
                        position[key] = (vi, vj)
                        queue.append((vi, vj))
                    elif position[key] != (vi, vj):
                        wraps = True
            if wraps:
                out["percolating"] += 1
                continue
            xs = np.array([p[0] for p in points], dtype=float)
            ys = np.array([p[1] for p in points], dtype=float)
            out["ext_x"] += len({int(x) % N for x in xs})
            out["ext_y"] += len({int(y) % M for y in ys})
            out["I_xx"] += ((xs - xs.mean()) ** 2).sum() + len(xs) / 12
            out["I_yy"] += ((ys - ys.mean()) ** 2).sum() + len(ys) / 12
    return out


def assert_same(m, ref):
    """Two Morphology results equal: counts exactly, floats to rounding (NaN matches NaN)."""
    assert (m.patches, m.percolating) == (ref.patches, ref.percolating)
    for name in ("area_fraction", "mean_patch_area", "perimeter", "anisotropy_extent", "anisotropy_moments"):
        np.testing.assert_allclose(getattr(m, name), getattr(ref, name), rtol=RTOL, err_msg=name)


def test_empty_map():
    m = contact_morphology(np.zeros((12, 20), dtype=bool), DX)
    assert (m.patches, m.percolating) == (0, 0)
    assert m.perimeter == 0 and m.area_fraction == 0
    assert math.isnan(m.mean_patch_area)
    assert math.isnan(m.anisotropy_extent) and math.isnan(m.anisotropy_moments)


def test_full_map_is_one_percolating_patch():
    m = contact_morphology(np.ones((12, 20), dtype=np.uint8), DX)
    assert (m.patches, m.percolating) == (1, 1)
    assert m.perimeter == 0
    assert m.area_fraction == 1
    np.testing.assert_allclose(m.mean_patch_area, 12 * 20 * DX**2, rtol=RTOL)
    assert math.isnan(m.anisotropy_extent) and math.isnan(m.anisotropy_moments)


def test_result_is_frozen():
    m = contact_morphology(rectangle((8, 8), 1, 1, 2, 2), DX)
    assert isinstance(m, Morphology)
    with pytest.raises(AttributeError):
        m.patches = 3


@pytest.mark.parametrize("a, b", [(7, 3), (1, 1), (2, 9)])
# interior, across x (rows N-1 | 0), across y (columns M-1 | 0), across both (the corner)
@pytest.mark.parametrize("x0, y0", [(4, 5), (16, 5), (4, 13), (17, 14)])
def test_rectangle_exact_and_shift_invariant(a, b, x0, y0):
    # The discrete variance of a run of a pixels is (a^2 - 1)/12; + 1/12 per pixel gives a^2/12, so
    # I_xx / I_yy = a^2 / b^2 for every placement.
    m = contact_morphology(rectangle((20, 16), x0, y0, a, b), DX)
    assert (m.patches, m.percolating) == (1, 0)
    np.testing.assert_allclose(m.area_fraction, a * b / (20 * 16), rtol=RTOL)
    np.testing.assert_allclose(m.mean_patch_area, a * b * DX**2, rtol=RTOL)
    np.testing.assert_allclose(m.perimeter, 2 * (a + b) * DX, rtol=RTOL)
    np.testing.assert_allclose(m.anisotropy_extent, a / b, rtol=RTOL)
    np.testing.assert_allclose(m.anisotropy_moments, a / b, rtol=RTOL)


def test_uint8_and_bool_agree():
    c = rectangle((10, 10), 8, 8, 4, 3) | rectangle((10, 10), 2, 2, 2, 5)
    assert_same(contact_morphology(c.astype(np.uint8), DX), contact_morphology(c, DX))


@pytest.mark.parametrize("axis", [0, 1])
def test_rectangles_touching_across_the_wrap_edge_are_one_patch(axis):
    # rows 0..3 and rows 17..19 of a 20-row map (columns overlapping on 7, 8) meet across x's edge
    c = rectangle((20, 16), 0, 5, 4, 4) | rectangle((20, 16), 17, 7, 3, 4)
    c = c if axis == 0 else c.T
    m = contact_morphology(c, DX)
    assert (m.patches, m.percolating) == (1, 0)
    # unwrapped, the same union sits in the interior: 7 rows x 6 columns, identical moments
    interior = contact_morphology(np.roll(c, 5, axis=axis), DX)
    ratio = 7 / 6 if axis == 0 else 6 / 7
    np.testing.assert_allclose(m.anisotropy_extent, ratio, rtol=RTOL)
    assert_same(m, interior)


@pytest.mark.parametrize("c, edges", [
    (rectangle((20, 16), 2, 2, 3, 3) | rectangle((20, 16), 5, 5, 3, 3), 2 * 12),  # inside the cell
    (rectangle((20, 16), 0, 0, 2, 2) | rectangle((20, 16), 18, 14, 2, 2), 2 * 8),  # across the corner
])
def test_diagonal_contact_does_not_join(c, edges):
    m = contact_morphology(c, DX)
    assert (m.patches, m.percolating) == (2, 0)
    np.testing.assert_allclose(m.perimeter, edges * DX, rtol=RTOL)


@pytest.mark.parametrize("axis", [0, 1])
def test_stripe_percolates_and_is_left_out_of_anisotropy(axis):
    stripe = np.zeros((20, 16), dtype=bool)
    if axis == 0:
        stripe[:, [15, 0]] = True  # spans x, itself cut by y's edge
    else:
        stripe[[19, 0], :] = True
    alone = contact_morphology(stripe, DX)
    assert (alone.patches, alone.percolating) == (1, 1)
    assert math.isnan(alone.anisotropy_extent) and math.isnan(alone.anisotropy_moments)

    m = contact_morphology(stripe | rectangle((20, 16), 5, 4, 5, 3), DX)
    assert (m.patches, m.percolating) == (2, 1)
    np.testing.assert_allclose(m.mean_patch_area, (stripe.sum() + 15) * DX**2 / 2, rtol=RTOL)
    np.testing.assert_allclose(m.anisotropy_extent, 5 / 3, rtol=RTOL)
    np.testing.assert_allclose(m.anisotropy_moments, 5 / 3, rtol=RTOL)


def test_diagonal_winding_percolates():
    # a staircase (k, k), (k, k+1) closes on itself after N steps along x and y at once
    n = 12
    k = np.arange(n)
    c = np.zeros((n, n), dtype=bool)
    c[k, k] = c[k, (k + 1) % n] = True
    m = contact_morphology(c, DX)
    assert (m.patches, m.percolating) == (1, 1)
    assert math.isnan(m.anisotropy_moments)


def test_open_staircase_longer_than_the_period():
    # (k, k), (k, k + 1) for k < 20 on a 12 x 30 cell: unwrapped it runs over 20 x indices, more than
    # the period, without meeting its own image (the y period is 30 > 21). It occupies all 12 x
    # indices and 21 y indices, and its moments are those of the unwrapped points.
    k = np.arange(20)
    x = np.concatenate([k, k])
    y = np.concatenate([k, k + 1])
    c = np.zeros((12, 30), dtype=bool)
    c[x % 12, y] = True
    m = contact_morphology(c, DX)
    assert (m.patches, m.percolating) == (1, 0)
    np.testing.assert_allclose(m.anisotropy_extent, 12 / 21, rtol=RTOL)
    moments = math.sqrt((x.var() + 1 / 12) / (y.var() + 1 / 12))
    np.testing.assert_allclose(m.anisotropy_moments, moments, rtol=RTOL)


def smooth_map(shape, fraction, sigma, seed):
    """Periodic smoothed white noise thresholded so that about `fraction` of it is in contact."""
    field = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), sigma, mode="wrap")
    return field > np.quantile(field, 1 - fraction)


def random_maps():
    """Seeded maps: uncorrelated pixels below and above site percolation, and smooth blobs."""
    cases = []
    for seed, shape in enumerate([(16, 16), (24, 40), (40, 28), (33, 17)]):
        rng = np.random.default_rng(100 + seed)
        for fraction in (0.2, 0.45, 0.65):
            cases.append((f"iid-{shape}-{fraction}", rng.random(shape) < fraction))
        for fraction in (0.1, 0.4, 0.6):
            cases.append((f"smooth-{shape}-{fraction}", smooth_map(shape, fraction, 1.5, seed)))
    return cases


@pytest.mark.parametrize("name, c", random_maps(), ids=[n for n, _ in random_maps()])
def test_random_maps_against_brute_force(name, c):
    ref = brute_force(c)
    m = contact_morphology(c, 1.0)  # dx = 1: the perimeter is the edge count itself
    assert (m.patches, m.percolating) == (ref["patches"], ref["percolating"])
    assert m.perimeter == ref["edges"]  # an integer below 2^53: exact in float64
    if ref["patches"] == ref["percolating"]:
        assert math.isnan(m.anisotropy_extent) and math.isnan(m.anisotropy_moments)
        return
    np.testing.assert_allclose(m.anisotropy_extent, ref["ext_x"] / ref["ext_y"], rtol=RTOL)
    np.testing.assert_allclose(m.anisotropy_moments, math.sqrt(ref["I_xx"] / ref["I_yy"]), rtol=RTOL)


def test_random_maps_cover_the_interesting_cases():
    # the brute-force comparison is only as strong as its maps: several must mix percolating and
    # non-percolating patches, and most must hold patches that the periodic edges cut into pieces
    maps = [c for _, c in random_maps()]
    found = [contact_morphology(c, 1.0) for c in maps]
    assert sum(0 < m.percolating < m.patches for m in found) >= 3
    assert sum(m.patches < ndimage.label(c)[1] for m, c in zip(found, maps)) >= len(maps) // 2


def test_periodic_shift_and_transpose():
    c = smooth_map((36, 28), 0.35, 2.0, seed=7)
    m = contact_morphology(c, DX)
    for shift in [(5, 0), (0, 9), (17, 11)]:
        assert_same(contact_morphology(np.roll(c, shift, axis=(0, 1)), DX), m)
    t = contact_morphology(c.T, DX)
    assert (t.patches, t.percolating) == (m.patches, m.percolating)
    np.testing.assert_allclose([t.area_fraction, t.mean_patch_area, t.perimeter],
                               [m.area_fraction, m.mean_patch_area, m.perimeter], rtol=RTOL)
    np.testing.assert_allclose(t.anisotropy_extent, 1 / m.anisotropy_extent, rtol=RTOL)
    np.testing.assert_allclose(t.anisotropy_moments, 1 / m.anisotropy_moments, rtol=RTOL)
    assert abs(math.log(m.anisotropy_moments)) > 1e-3  # the inversion is not trivially 1 = 1 / 1


@pytest.mark.parametrize("shift", [(0, 0), (64, 32)])  # centred, then cut by both edges
def test_ellipse_anisotropy(shift):
    # Semi-axes A = 40 along x, B = 20 along y. The continuous ellipse has I_xx / I_yy = A^2 / B^2;
    # the digitised boundary moves the ratio by O(1 / B) of the boundary pixels' share (0.4 % here),
    # hence 1 %. The extents are 2A + 1 and 2B + 1 pixels: 81 / 41 = (A / B)(1 - 1.2 %), hence 3 %.
    A, B, N, M = 40, 20, 128, 64
    i = np.arange(N)[:, None] - N // 2
    j = np.arange(M)[None, :] - M // 2
    c = np.roll((i / A) ** 2 + (j / B) ** 2 <= 1, shift, axis=(0, 1))
    m = contact_morphology(c, DX)
    assert (m.patches, m.percolating) == (1, 0)
    np.testing.assert_allclose(m.anisotropy_moments, A / B, rtol=0.01)
    np.testing.assert_allclose(m.anisotropy_extent, A / B, rtol=0.03)
    np.testing.assert_allclose(m.anisotropy_extent, (2 * A + 1) / (2 * B + 1), rtol=RTOL)


@pytest.mark.parametrize("contact, spacing, message", [
    (np.zeros(8, dtype=bool), DX, "2-D"),
    (np.zeros((4, 4, 4), dtype=bool), DX, "2-D"),
    (np.zeros((0, 4), dtype=bool), DX, "2-D"),
    (np.full((4, 4), 2, dtype=np.uint8), DX, "0 and 1"),
    (np.full((4, 4), "a"), DX, "0 and 1"),
    (np.zeros((4, 4), dtype=bool), 0.0, "spacing"),
    (np.zeros((4, 4), dtype=bool), -DX, "spacing"),
    (np.zeros((4, 4), dtype=bool), math.nan, "spacing"),
    (np.zeros((4, 4), dtype=bool), math.inf, "spacing"),
    (np.zeros((4, 4), dtype=bool), "1e-6 m", "spacing"),
])
def test_bad_input(contact, spacing, message):
    with pytest.raises(ValueError, match=message):
        contact_morphology(contact, spacing)
