"""The cube map: ImfEnvmap layout, texel binning, footprint solid angles, sampling.

The decisive tests compare with OpenEXR's own C++ ``ImfEnvmap`` through a small probe
(``tests/imf_envmap_probe.cpp``) compiled against the system OpenEXR headers
(``apt-get install libopenexr-dev pkg-config``, plus g++). Set ``LUMITRACE_SKIP_NATIVE=1``
to skip them where those cannot be installed.
"""
from __future__ import annotations


import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from lumitrace.film import cubemap as cm
from helpers.paths import TESTS

HERE = TESTS
FOUR_PI = 4.0 * np.pi


def uniform_directions(n: int, seed: int) -> np.ndarray:
    """n directions uniform on the sphere (normalised Gaussian vectors)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# --------------------------------------------------------------------------- layout


def test_face_size_and_shape():
    assert cm.face_size(6) == 1
    assert cm.face_size(6 * 256) == 256
    assert cm.image_shape(7) == (42, 7)
    for bad in (0, 5, 13, -6):
        with pytest.raises(ValueError):
            cm.face_size(bad)
    for bad in (0, -1, 2.5):
        with pytest.raises(ValueError):
            cm.image_shape(bad)


def test_face_table_matches_envmap_header_diagram():
    # ImfEnvmap.h draws each face with cube corners 0..7 at its image corners.
    corner = {i: np.array([1 if i & 1 else -1, 1 if i & 2 else -1, 1 if i & 4 else -1])
              for i in range(8)}
    # (top-left, top-right, bottom-left, bottom-right) per face, from the header.
    drawn = {cm.POS_X: (3, 7, 1, 5), cm.NEG_X: (6, 2, 4, 0), cm.POS_Y: (6, 7, 2, 3),
             cm.NEG_Y: (0, 1, 4, 5), cm.POS_Z: (7, 6, 5, 4), cm.NEG_Z: (2, 3, 0, 1)}
    res = 5
    dirs = cm.texel_directions(res)
    for face, corners in drawn.items():
        block = dirs[face * res:(face + 1) * res]
        got = [block[0, 0], block[0, -1], block[-1, 0], block[-1, -1]]
        for d, c in zip(got, corners):
            assert_allclose(d, corner[c] / np.sqrt(3.0), atol=1e-15, err_msg=cm.FACE_NAMES[face])
        centre = block[res // 2, res // 2]
        expected = np.zeros(3)
        expected[cm.FACE_AXIS[face]] = cm.FACE_SIGN[face]
        assert_allclose(centre, expected, atol=1e-15)


def test_texel_directions_are_unit_and_on_their_face():
    for res in (1, 2, 3, 8):
        d = cm.texel_directions(res)
        assert d.shape == (6 * res, res, 3) and d.dtype == np.float64
        assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-15)
        face = np.arange(6 * res) // res
        major = d[np.arange(6 * res), :, cm.FACE_AXIS[face]]
        assert np.all(major * cm.FACE_SIGN[face][:, None] > 0)
        assert np.all(np.abs(major) >= np.abs(d).max(axis=-1))


# ------------------------------------------------------------------- solid angles


@pytest.mark.parametrize("res", [1, 2, 3, 4, 5, 16, 63, 64, 256, 1024])
def test_solid_angles_sum_to_four_pi(res):
    omega = cm.texel_solid_angles(res)
    assert omega.shape == (6 * res, res) and omega.dtype == np.float64
    assert np.all(omega > 0)
    assert abs(omega.sum() - FOUR_PI) < 1e-12


def test_solid_angles_of_small_maps():
    assert_allclose(cm.texel_solid_angles(1), FOUR_PI / 6, rtol=1e-15)
    assert_allclose(cm.texel_solid_angles(2), FOUR_PI / 24, rtol=1e-15)
    # res 3: corner quarter cells, edge half cells, one full centre cell of [-1/2, 1/2]^2.
    centre = 4 * np.arctan(0.25 / np.sqrt(1.5))
    assert_allclose(cm.face_solid_angles(3)[1, 1], centre, rtol=1e-15)


@pytest.mark.parametrize("res", [2, 3, 4, 7, 32])
def test_solid_angles_are_symmetric(res):
    face = cm.face_solid_angles(res)
    assert_array_equal(face, face.T)
    assert_array_equal(face, face[::-1, :])
    assert_array_equal(face, face[:, ::-1])
    omega = cm.texel_solid_angles(res)
    for f in range(6):
        assert_array_equal(omega[f * res:(f + 1) * res], face)


def corner_formula(a0, a1, b0, b1):
    def f(a, b):
        return np.arctan2(a * b, np.sqrt(1.0 + a * a + b * b))
    return f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)


def test_rectangle_solid_angle_matches_corner_formula():
    rng = np.random.default_rng(7)
    a = np.sort(rng.uniform(-1, 1, size=(1000, 2)), axis=1)
    b = np.sort(rng.uniform(-1, 1, size=(1000, 2)), axis=1)
    got = cm.rectangle_solid_angle(a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    ref = corner_formula(a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    assert_allclose(got, ref, rtol=1e-9)  # the corner formula itself loses ~eps/width^2
    assert_allclose(cm.rectangle_solid_angle(-1, 1, -1, 1), FOUR_PI / 6, rtol=1e-15)


def test_footprint_solid_angles_by_quadrature():
    from scipy.integrate import dblquad

    res = 6
    s = res - 1
    face = cm.face_solid_angles(res)
    h = 2.0 / s
    for px, py in [(0, 0), (0, 2), (3, 1), (5, 5), (2, 2)]:
        a0, a1 = max(-1.0, -1 + (px - 0.5) * h), min(1.0, -1 + (px + 0.5) * h)
        b0, b1 = max(-1.0, -1 + (py - 0.5) * h), min(1.0, -1 + (py + 0.5) * h)
        value, _ = dblquad(lambda b, a: (1 + a * a + b * b) ** -1.5, a0, a1, b0, b1,
                           epsabs=0, epsrel=1e-13)
        assert_allclose(face[py, px], value, rtol=1e-11)


# ------------------------------------------------------------------ texel binning


@pytest.mark.parametrize("res", [1, 2, 3, 4, 9, 32])
def test_texel_index_round_trips_texel_directions(res):
    dirs = cm.texel_directions(res).reshape(-1, 3)
    idx = cm.texel_index(dirs, res)
    own = np.arange(6 * res * res)
    # Every texel's direction lands on a texel with exactly the same pixel position ...
    assert_array_equal(dirs[idx], dirs)
    # ... which is the texel itself except for the positions that faces share on the
    # cube's edges (2 texels) and corners (3 texels): those go to the preferred face.
    moved = idx != own
    if res == 1:
        assert not moved.any()
    else:
        assert moved.sum() == 12 * (res - 2) + 8 * 2
        rows = own[moved] // res
        assert np.all(cm.FACE_AXIS[rows // res] > cm.FACE_AXIS[idx[moved] // res // res])
    # The texel at the destination is canonical: it maps to itself.
    assert_array_equal(cm.texel_index(dirs[idx], res), idx)
    assert_array_equal(cm.canonical_texels(res).ravel(), idx)


def test_texel_index_of_edges_corners_and_degenerate_directions():
    res = 8
    lattice = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)
                        if (x, y, z) != (0, 0, 0)], dtype=np.float64)
    tiny = 5e-324
    extra = np.array([[0.0, 0.0, 0.0], [-0.0, -0.0, -0.0], [1e308, -1e308, 1e308],
                      [tiny, tiny, -tiny], [tiny, 0, 0], [0, -tiny, 0], [-0.0, 0.0, 1.0],
                      [1.0, 1.0, np.nextafter(1.0, 2.0)], [1.0, np.nextafter(1.0, 0), 0.0]])
    dirs = np.concatenate([lattice, lattice * 1e-300, lattice * 1e300, extra])
    idx = cm.texel_index(dirs, res)
    assert idx.dtype == np.int64
    assert np.all((idx >= 0) & (idx < 6 * res * res))
    face, pif = cm.face_and_pixel_position(dirs, res)
    # ImfEnvmap's tie rule: X before Y before Z; zero components count as negative.
    assert face[list(map(tuple, lattice)).index((1.0, 1.0, 1.0))] == cm.POS_X
    assert face[list(map(tuple, lattice)).index((0.0, 1.0, 1.0))] == cm.POS_Y
    assert face[list(map(tuple, lattice)).index((0.0, -1.0, -1.0))] == cm.NEG_Y
    assert face[len(lattice) * 3] == cm.POS_X and tuple(pif[len(lattice) * 3]) == (0, 0)
    assert face[len(lattice) * 3 + 6] == cm.POS_Z
    assert np.all((pif >= 0) & (pif <= res - 1))
    # Directions on an edge bin into an edge texel of the preferred face.
    on_edge = cm.texel_index(np.array([[1.0, 1.0, 0.3]]), res)[0]
    assert on_edge // res // res == cm.POS_X
    with pytest.raises(ValueError):
        cm.texel_index(np.array([[np.nan, 0, 1]]), res)
    with pytest.raises(ValueError):
        cm.texel_index(np.array([[np.inf, 0, 1]]), res)
    with pytest.raises(ValueError):
        cm.texel_index(np.zeros((3, 2)), res)


def test_texel_index_does_not_need_normalised_directions():
    d = uniform_directions(100_000, seed=11)
    res = 16
    ref = cm.texel_index(d, res)
    for scale in (2.0**-60, 2.0**50, 3.7, 1e-3, 1e200):
        assert_array_equal(cm.texel_index(d * scale, res), ref)


@pytest.mark.parametrize("res", [1, 2, 5, 16])
def test_random_directions_land_in_the_nearest_pixel_position(res):
    """Brute force: among the texels of the direction's face, the nearest pixel position."""
    d = uniform_directions(20_000, seed=res)
    idx = cm.texel_index(d, res)
    texel_dirs = cm.texel_directions(res)
    axis = np.argmax(np.abs(d), axis=1)
    sign = np.sign(d[np.arange(len(d)), axis])
    for face in range(6):
        sel = (axis == cm.FACE_AXIS[face]) & (sign == cm.FACE_SIGN[face])
        q = d[sel] / np.abs(d[sel, cm.FACE_AXIS[face]])[:, None]  # point on the cube
        block = texel_dirs[face * res:(face + 1) * res].reshape(-1, 3)
        p = block / np.abs(block[:, cm.FACE_AXIS[face]])[:, None]
        dist = ((q[:, None, :] - p[None, :, :]) ** 2).sum(axis=-1)
        nearest = face * res * res + np.argmin(dist, axis=1)
        assert_array_equal(idx[sel], nearest)


def test_footprints_contain_their_directions():
    res = 7
    s = res - 1
    d = uniform_directions(50_000, seed=3)
    face, pif = cm.face_and_pixel_position(d, res)
    idx = cm.texel_index(d, res)
    # Footprint of pixel i along one axis: face coordinates [(2i-1-s)/s, (2i+1-s)/s] clipped.
    ab = 2 * pif / s - 1
    ip = np.rint(pif)
    lo = np.maximum(-1, (2 * ip - 1 - s) / s)
    hi = np.minimum(1, (2 * ip + 1 - s) / s)
    assert np.all((ab >= lo - 1e-12) & (ab <= hi + 1e-12))
    pos = cm.pixel_position(face, ip, res)
    assert_array_equal(idx, (pos[:, 1] * res + pos[:, 0]).astype(np.int64))


@pytest.mark.parametrize("res", [3, 4, 9])
def test_uniform_directions_fill_texels_by_solid_angle(res):
    from scipy.stats import chisquare

    n = 1_000_000
    d = uniform_directions(n, seed=20240 + res)
    counts = np.bincount(cm.texel_index(d, res), minlength=6 * res * res)
    expected = n * cm.texel_solid_angles(res).ravel() / FOUR_PI
    assert abs(expected.sum() - n) < 1e-6
    assert chisquare(counts, expected).pvalue > 1e-3
    # The test has power: full cells for edge texels (the wrong footprint) are rejected.
    wrong = np.ones((res, res))
    wrong /= wrong.sum()
    wrong = np.tile(wrong, (6, 1)).ravel() * n / 6
    assert chisquare(counts, wrong).pvalue < 1e-12


# ---------------------------------------------------------------------- sampling


def test_sample_map_reproduces_functions_linear_on_faces():
    res = 6
    td = cm.texel_directions(res)
    on_cube = td / np.abs(td).max(axis=-1, keepdims=True)  # ImfEnvmap's direction()
    d = np.concatenate([uniform_directions(5000, seed=5), td.reshape(-1, 3),
                        [[1, 1, 1], [0, 0, -2], [1, -1, 0.25]]])
    got = cm.sample_map(on_cube, d)
    assert got.shape == (len(d), 3)
    assert_allclose(got, d / np.abs(d).max(axis=1, keepdims=True), atol=1e-13)
    single = cm.sample_map(on_cube[..., 2], d)
    assert single.shape == (len(d),)
    assert_allclose(single, got[:, 2], atol=0)


def test_sample_map_at_texels_and_constants():
    for res in (1, 2, 5):
        rng = np.random.default_rng(res)
        image = rng.uniform(size=cm.image_shape(res))
        dirs = cm.texel_directions(res).reshape(-1, 3)
        canon = cm.canonical_texels(res).ravel()
        assert_allclose(cm.sample_map(image, dirs), image.ravel()[canon], rtol=1e-14)
        assert_allclose(cm.sample_map(np.full(cm.image_shape(res), 2.5),
                                      uniform_directions(1000, seed=1)), 2.5, rtol=1e-15)
    with pytest.raises(ValueError):
        cm.sample_map(np.zeros((10, 2)), dirs)


def test_weld_seams_merges_shared_positions_and_keeps_flux():
    res = 5
    rng = np.random.default_rng(9)
    image = rng.uniform(1, 2, size=cm.image_shape(res))
    omega = cm.texel_solid_angles(res)
    welded = cm.weld_seams(image)
    assert_allclose((welded * omega).sum(), (image * omega).sum(), rtol=1e-14)
    canon = cm.canonical_texels(res).ravel()
    flat = welded.ravel()
    assert_allclose(flat, flat[canon], rtol=1e-15)
    interior = np.bincount(canon, minlength=canon.size)[canon] == 1
    assert_array_equal(flat[interior], image.ravel()[interior])
    # Welded maps sample continuously across edges.
    eps = 1e-9
    edge = np.array([[1.0, 1.0 - eps, 0.3], [1.0 - eps, 1.0, 0.3]])
    a, b = cm.sample_map(welded, edge)
    assert abs(a - b) < 1e-6
    stacked = cm.weld_seams(np.stack([image, 2 * image], axis=-1))
    assert_allclose(stacked[..., 1], 2 * welded, rtol=1e-15)


def test_latlong_directions():
    d = cm.latlong_directions(4)
    assert d.shape == (4, 8, 3)
    assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-15)
    assert_allclose(d[0, :, 1], 1.0)  # first row: +Y
    assert_allclose(d[-1, :, 1], -1.0)


# ------------------------------------------------------- OpenEXR's ImfEnvmap oracle


def _f32_text(x: float) -> str:
    return repr(float(np.float32(x)))


def oracle_directions() -> np.ndarray:
    """Float32-exact directions: random, axes, edges, corners, lattice points, near ties."""
    rng = np.random.default_rng(2718)
    rand = rng.normal(size=(3000, 3)) * rng.choice([1e-3, 1.0, 7.0, 1e4], size=(3000, 1))
    lattice = np.array([(x, y, z) for x in range(-2, 3) for y in range(-2, 3)
                        for z in range(-2, 3)], dtype=np.float64)
    one_minus = float(np.nextafter(np.float32(1), np.float32(0)))
    ties = np.array([[1, one_minus, 0.5], [one_minus, 1, -0.5], [0.25, -1, one_minus],
                     [-0.0, -0.0, 1.0], [0.0, -0.0, -1.0], [-0.0, 1.0, 0.0],
                     [-3.0, 3.0, 3.0], [0.5, -0.5, -0.5]])
    # Directions onto exact texel boundaries and pixel positions of a 5-texel face.
    grid = np.array([(1.0, a, b) for a in np.linspace(-1, 1, 9) for b in (-1.0, 0.25, 1.0)])
    d = np.concatenate([rand, lattice, ties, grid, -grid[:, [2, 0, 1]]])
    return d.astype(np.float32).astype(np.float64)


@pytest.mark.parametrize("res", [1, 2, 3, 5, 8, 64, 513])
def test_face_and_pixel_position_match_imf_envmap(imf_probe, res):
    d = oracle_directions()
    out = imf_probe([f"F {res} " + " ".join(_f32_text(v) for v in row) for row in d])
    assert out.shape == (len(d), 5)
    face, pif = cm.face_and_pixel_position(d, res)
    tol = 1e-6 * max(1, res - 1)
    assert_array_equal(face, out[:, 0].astype(np.int64))
    assert_allclose(pif, out[:, 1:3], rtol=0, atol=tol)
    pos = cm.pixel_position(face, pif, res)
    assert_allclose(pos, out[:, 3:5], rtol=0, atol=tol)
    # The texel is the pixel nearest ImfEnvmap's position (where rounding is unambiguous).
    frac = np.abs(out[:, 3:5] - np.floor(out[:, 3:5]) - 0.5)
    clear = np.all(frac > 1e-4, axis=1)
    assert clear.sum() > 0.9 * len(d)
    col_row = np.floor(out[clear, 3:5] + 0.5).astype(np.int64)
    assert_array_equal(cm.texel_index(d[clear], res), col_row[:, 1] * res + col_row[:, 0])


@pytest.mark.parametrize("res", [1, 2, 3, 5, 8, 33])
def test_texel_directions_match_imf_envmap(imf_probe, res):
    faces, pys, pxs = np.meshgrid(np.arange(6), np.arange(res), np.arange(res), indexing="ij")
    faces, pxs, pys = faces.ravel(), pxs.ravel(), pys.ravel()
    out = imf_probe([f"D {res} {f} {x} {y}" for f, x, y in zip(faces, pxs, pys)])
    col, row = out[:, 3], out[:, 4]
    assert_array_equal(col, np.round(col))  # integer positions in face are image pixels
    pif = np.stack([pxs, pys], axis=-1)
    assert_array_equal(cm.pixel_position(faces, pif, res), out[:, 3:5])
    # Every image pixel is covered exactly once.
    flat = (row * res + col).astype(np.int64)
    assert_array_equal(np.sort(flat), np.arange(6 * res * res))
    ours = cm.texel_directions(res)[row.astype(np.int64), col.astype(np.int64)]
    theirs = out[:, :3] / np.linalg.norm(out[:, :3], axis=1, keepdims=True)
    assert_allclose(ours, theirs, rtol=0, atol=1e-6)
    assert_allclose(cm.direction(faces, pif, res, normalize=False), out[:, :3], atol=1e-6)


def test_continuous_directions_match_imf_envmap(imf_probe):
    rng = np.random.default_rng(31)
    res = 17
    faces = rng.integers(0, 6, size=2000)
    pif = rng.uniform(0, res - 1, size=(2000, 2)).astype(np.float32).astype(np.float64)
    out = imf_probe([f"D {res} {f} {_f32_text(x)} {_f32_text(y)}"
                     for f, (x, y) in zip(faces, pif)])
    assert_allclose(cm.direction(faces, pif, res, normalize=False), out[:, :3], atol=1e-6)
    assert_allclose(cm.pixel_position(faces, pif, res), out[:, 3:5], atol=1e-5)
    # faceAndPixelPosition inverts direction.
    face2, pif2 = cm.face_and_pixel_position(out[:, :3], res)
    inside = np.all((pif > 1e-3) & (pif < res - 1 - 1e-3), axis=1)
    assert_array_equal(face2[inside], faces[inside])
    assert_allclose(pif2[inside], pif[inside], atol=1e-5)


def test_latlong_directions_match_imf_envmap(imf_probe):
    height, width = 9, 18
    ys, xs = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    out = imf_probe([f"L {width} {height} {x} {y}" for x, y in zip(xs.ravel(), ys.ravel())])
    assert_allclose(cm.latlong_directions(height, width).reshape(-1, 3), out, atol=1e-6)
