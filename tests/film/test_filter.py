"""The pull-push filter and the error estimates, against closed forms."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from lumitrace.film.convergence import estimate, relative_rms
from lumitrace.film.cubemap import canonical_texels, texel_directions, texel_solid_angles
from lumitrace.film.pullpush import pull_push
from lumitrace.film.texel_quadrature import texel_integrals
from helpers.reference import expected_counts, trace

RES = 32


def _closed_form_map(expectation: dict, photons: int) -> np.ndarray:
    """The closed form's texel means (cd) as ``photons`` photons of a 1000 lm source see it."""
    return expected_counts(expectation, RES, photons) * 1000.0 / photons / texel_solid_angles(RES)


def _counts(seed, lam=0.7):
    return np.random.default_rng(seed).poisson(lam, size=(6 * RES, RES)).astype(np.int64)


def test_threshold_zero_returns_the_raw_map():
    omega = texel_solid_angles(RES)
    counts = _counts(1)
    flux = counts * 0.01
    assert np.array_equal(pull_push(flux, counts, 0.0), flux / omega)


def test_total_flux_is_kept():
    omega = texel_solid_angles(RES)
    counts = _counts(2, 0.3)
    flux = counts * 0.013
    out = pull_push(flux, counts, 40.0)
    assert (out * omega).sum() == pytest.approx(flux.sum(), rel=1e-12)
    assert np.all(out >= 0)


def test_constant_map_stays_constant_everywhere_including_seams():
    omega = texel_solid_angles(RES)
    counts = _counts(3, 0.2)  # mostly empty texels: values come from coarse levels
    out = pull_push(5.0 * omega, counts, 16.0)
    np.testing.assert_allclose(out, 5.0, rtol=1e-12)


def test_shared_edge_texels_agree_and_smooth_maps_have_no_seams():
    omega = texel_solid_angles(RES)
    d = texel_directions(RES)
    truth = 100.0 * (1.2 + d[..., 0] + 0.5 * d[..., 2])  # smooth, positive
    counts = _counts(4, 3.0)
    rng = np.random.default_rng(5)
    flux = truth * omega * rng.gamma(4.0, 0.25, size=truth.shape)  # noisy texels
    out = pull_push(flux, counts, 32.0)
    canon = canonical_texels(RES).ravel()
    flat = out.ravel()
    assert np.array_equal(flat, flat[canon])  # one value per shared position
    # the edge texels are shared by the faces they join, so a seam would show as a jump
    # between an edge texel and its inward neighbour: no larger than steps inside a face
    faces = out.reshape(6, RES, RES)
    steps = np.abs(np.diff(faces, axis=2))
    at_edges = np.concatenate([steps[:, :, 0], steps[:, :, -1]]).max()
    inside = steps[:, :, 2:-2].max()
    assert at_edges <= 1.5 * inside


def test_converges_to_the_raw_map_as_counts_grow():
    omega = texel_solid_angles(RES)
    counts = np.full((6 * RES, RES), 1000, np.int64)
    rng = np.random.default_rng(6)
    flux = omega * rng.uniform(50, 150, size=counts.shape)
    out = pull_push(flux, counts, 32.0)
    interior = canonical_texels(RES) == np.arange(6 * RES * RES).reshape(6 * RES, RES)
    edge = np.zeros_like(interior)
    for f in range(6):
        block = np.zeros((RES, RES), bool)
        block[1:-1, 1:-1] = True
        edge[f * RES:(f + 1) * RES] = block
    raw = flux / omega
    # every texel trusts itself: interior texels keep their raw value (up to the flux
    # renormalisation, which the welded seams change by a hair)
    np.testing.assert_allclose(out[edge], raw[edge], rtol=2e-3)
    assert interior.sum() > edge.sum()


@pytest.fixture(scope="module")
def disc_low():
    scene, result, exp = trace("lambertian_disc", 20_000, res=RES, seed=11)
    ref = _closed_form_map(exp, 20_000)
    return result.accumulator, ref


def test_filtered_lambertian_disc_beats_raw_by_two_at_low_counts(disc_low):
    acc, ref = disc_low
    e = estimate(acc, 64.0)
    raw_err, filt_err = relative_rms(e.raw, ref), relative_rms(e.filtered, ref)
    assert filt_err * 2 <= raw_err, (raw_err, filt_err)


@pytest.mark.parametrize("name", ["lambertian_disc", "mirror_cup"])
@pytest.mark.parametrize("seed", [0, 1])
def test_sharpening_takes_out_the_blend_bias_on_curved_lobes(name, seed):
    """Poisson counts of the closed form at 300k photons: the residual filtered again (twicing)
    cuts the map's true error by a fifth or more against one pass (measured 0.70-0.78), and
    the map stays non-negative with its flux."""
    _, _, exp = trace(name, 10, res=RES, seed=1)
    lam = expected_counts(exp, RES, 300_000)
    ref = _closed_form_map(exp, 300_000)
    counts = np.random.default_rng(seed).poisson(lam)
    flux = counts * 1000.0 / 300_000
    omega = texel_solid_angles(RES)
    once = relative_rms(pull_push(flux, counts, 1e4, omega, sharpen=False), ref)
    sharp_map = pull_push(flux, counts, 1e4, omega)
    sharp = relative_rms(sharp_map, ref)
    assert sharp <= 0.85 * once, (once, sharp)
    assert sharp < 0.4 * relative_rms(flux / omega, ref)
    assert sharp_map.min() >= 0
    assert (sharp_map * omega).sum() == pytest.approx(flux.sum(), rel=1e-12)


@pytest.mark.parametrize("name,photons,threshold", [
    ("lambertian_disc", 100_000, 0.0), ("lambertian_disc", 100_000, 32.0),
    ("lambertian_disc", 100_000, 128.0), ("isotropic", 100_000, 32.0),
    ("fresnel_slab", 100_000, 64.0), ("lambertian_disc", 400_000, 32.0),
    # the default threshold, where the filter adapts to its photons
    ("isotropic", 100_000, 1e4), ("mirror_cup", 300_000, 1e4), ("fresnel_slab", 300_000, 1e4)])
def test_estimated_error_is_honest(name, photons, threshold):
    _, result, exp = trace(name, photons, res=RES, seed=21)
    ref = _closed_form_map(exp, photons)
    e = estimate(result.accumulator, threshold)
    true = relative_rms(e.filtered, ref)
    assert true / 1.5 <= e.error <= true * 1.5, (true, e.error)
    assert relative_rms(e.raw, ref) / 1.5 <= e.raw_error <= relative_rms(e.raw, ref) * 1.5


@functools.lru_cache(maxsize=None)
def _estimates_at_default(name: str, photons: int = 300_000) -> list:
    """(estimate at the default threshold, its map's true error) for seeds 21-24."""
    out = []
    for seed in (21, 22, 23, 24):
        _, result, exp = trace(name, photons, res=RES, seed=seed)
        e = estimate(result.accumulator, 1e4)
        out.append((e, relative_rms(e.filtered, _closed_form_map(exp, photons))))
    return out


def test_estimated_error_is_not_optimistic_where_the_filter_adapts():
    """The mirror cup's steps at the default threshold: the filter trusts texels that depart
    from their neighbours, and that choice is part of its noise. Halves filtered with the
    whole map's weights missed it (the estimate 0.83 of the true error on average over
    these seeds, 0.65 at worst); each half filtered on its own photons (at half the
    threshold) sees it (1.06, 0.92 at worst)."""
    ratios = [e.error / true for e, true in _estimates_at_default("mirror_cup")]
    assert 0.9 <= np.mean(ratios) <= 1.4, ratios
    assert min(ratios) >= 0.75, ratios


@pytest.mark.parametrize("seed", [1, 2])
def test_a_cut_off_angle_stays_as_sharp_as_the_counts_show_it(seed):
    """A beam of 300 cd with a cut-off at 26.6 deg from the nadir over 60 cd elsewhere (the
    white cup's direct light), Poisson counts of 1M photons: within 5 deg of the cut-off
    the filtered map is no worse than the raw one (tested on each group's mean alone, the
    edge ran through groups unseen and the ring's error was 1.4x the raw map's), and over
    the sphere it is better by 2.5x or more (measured 2.7-2.8x)."""
    omega = texel_solid_angles(RES)
    integ = texel_integrals(lambda d: np.where(-d[:, 2] > np.cos(np.radians(26.6)), 300.0,
                                               60.0), RES)
    truth, photons = integ / omega, 1_000_000
    counts = np.random.default_rng(seed).poisson(photons * integ / integ.sum())
    flux = counts * integ.sum() / photons
    out = pull_push(flux, counts, 1e4, omega)
    gamma = np.degrees(np.arccos(np.clip(-texel_directions(RES)[..., 2], -1.0, 1.0)))
    ring = np.abs(gamma - 26.6) < 5.0

    def error(image, where):
        return np.sqrt((omega * (image - truth) ** 2)[where].sum()
                       / (omega * truth ** 2)[where].sum())

    everywhere = np.ones_like(ring)
    assert error(out, ring) <= 1.1 * error(flux / omega, ring)
    assert error(out, everywhere) <= error(flux / omega, everywhere) / 2.5


@pytest.mark.parametrize("name", ["mirror_cup", "lambertian_disc"])
def test_the_error_bound_is_above_the_true_error_and_not_far(name):
    """What convergence is judged on: the estimate with its bias term's spread added is at
    or above the true error in every seed here (the point estimate was below it in three of
    eight, down to 0.68 of it), and within twice it (measured 1.08-1.81)."""
    for e, true in _estimates_at_default(name):
        assert true <= e.error_bound <= 2.0 * true, (true, e.error, e.error_bound)
        assert e.error_bound >= e.error


@pytest.mark.parametrize("res", [2, 8, 33, 64])
def test_the_compiled_push_gives_numpys_bits(res, monkeypatch):
    """The tracer's compiled push (registered when its kernels load) and the film's numpy
    push filter to the same bits: adaptive or not, sharpened or not, with colour channels,
    and replaying the weights of a first map on a second (split halves)."""
    from lumitrace.film import pullpush
    from lumitrace.trace import compiled

    assert pullpush.compiled_level is compiled.push_level
    rng = np.random.default_rng(res)
    omega = texel_solid_angles(res)
    shape = np.ones((6 * res, res))
    shape[: max(1, res // 2)] *= 40.0  # a bright face and a beam's edge across it
    shape[3 * res:3 * res + max(1, res // 8)] *= 300.0

    def filtered():
        out = []
        for lam in (0.3, 5.0, 300.0):
            counts = rng.poisson(lam * shape / shape.mean())
            flux = counts * 0.37
            out.append(pull_push(flux, counts, 1e4, omega))
            out.append(pull_push(flux, counts, 2500.0, omega, sharpen=False))
            out.append(pull_push(flux, counts, 1e4, omega, adaptive=False))
            weights = []
            out.append(pull_push(flux, counts, 5000.0, omega, weights=weights))
            out.append(pull_push(flux * 0.5, counts // 2, 5000.0, omega, weights=weights))
            y, xz = pull_push(flux, counts, 1e4, omega,
                              extra=np.stack([flux * 0.3, flux * 1.1 + 0.01 * counts]))
            out += [y, xz]
        return out

    state = rng.bit_generator.state
    compiled_maps = filtered()
    rng.bit_generator.state = state
    monkeypatch.setattr(pullpush, "compiled_level", None)
    for a, b in zip(compiled_maps, filtered()):
        assert np.array_equal(a, b)
