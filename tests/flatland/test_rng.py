"""Random streams: sequential per name, and counter-based draws keyed on sample indices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from flatland.core.rng import Draws, keyed_bits, keyed_normals, keyed_uniforms, mix64, stream
from flatland.core.stats import chi2_gof, sidak

ALPHA = 1e-3
GOF_TESTS = 2  # chi-square tests in this file, for the Šidák correction
BINS = 41


def test01_mix64_gives_the_splitmix64_reference_sequence():
    # SplitMix64 from seed 0: state k * 0x9E3779B97F4A7C15, output mix64(state) (the reference sequence)
    state = np.arange(1, 5, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    expected = [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F, 0xF88BB8A8724C81EC]
    np.testing.assert_array_equal(mix64(state), np.array(expected, dtype=np.uint64))


def test01b_neighbouring_keys_give_uncorrelated_words():
    # consecutive sample indices (the common case) and the two paths of one sample: each output bit
    # is set with probability 1/2 and independent of the same bit of the neighbour's word
    bits = keyed_bits(5, "samples", np.arange(20_001), 2)
    a, b = bits[:-1, 0], bits[1:, 0]
    for bit in range(0, 64, 7):
        x = ((a >> np.uint64(bit)) & np.uint64(1)).astype(float)
        y = ((b >> np.uint64(bit)) & np.uint64(1)).astype(float)
        # |corr| of two independent fair bits over n pairs is below z / sqrt(n) (z = 4.5, Sidak over 10)
        assert abs(np.corrcoef(x, y)[0, 1]) < 4.5 / np.sqrt(x.size)
        assert abs(x.mean() - 0.5) < 4.5 * 0.5 / np.sqrt(x.size)


def test02_a_rows_numbers_depend_only_on_its_key():
    keys = np.array([[7, 0], [3, 1], [3, 0], [123456789, 5]])
    whole = keyed_uniforms(1, "kernel", keys, 9)
    perm = np.array([2, 0, 3, 1])
    np.testing.assert_array_equal(keyed_uniforms(1, "kernel", keys[perm], 9), whole[perm])
    np.testing.assert_array_equal(keyed_uniforms(1, "kernel", keys[1:2], 9), whole[1:2])
    np.testing.assert_array_equal(keyed_uniforms(1, "kernel", keys, 3), whole[:, :3])  # a prefix
    assert not np.any(keyed_uniforms(2, "kernel", keys, 9) == whole)  # another seed
    assert not np.any(keyed_uniforms(1, "probes", keys, 9) == whole)  # another stream
    assert keyed_bits(1, "kernel", keys, 5).dtype == np.uint64


def test03_keyed_uniforms_are_uniform():
    u = keyed_uniforms(11, "samples", np.arange(40_000), 5).ravel()
    assert u.min() >= 0.0 and u.max() < 1.0
    result = chi2_gof(u, lambda x: np.ones_like(x), BINS, (0.0, 1.0))
    assert result.passed(sidak(ALPHA, GOF_TESTS)), result


def test04_keyed_normals_are_standard_normal_and_finite():
    z = keyed_normals(11, "kernel", np.arange(40_000), 5).ravel()
    assert np.all(np.isfinite(z))
    result = chi2_gof(z, stats.norm.pdf, BINS, (-4.0, 4.0))
    assert result.passed(sidak(ALPHA, GOF_TESTS)), result


def test05_draws_follow_the_row_operations_with_distinct_keys():
    d = Draws.of(3, np.array([10, 11, 12]))
    tiled, repeated = d.tile(2), d.repeat(2)
    np.testing.assert_array_equal(tiled.sample, [10, 11, 12, 10, 11, 12])
    np.testing.assert_array_equal(repeated.sample, [10, 10, 11, 11, 12, 12])
    for rows in (tiled, repeated, tiled.repeat(2)):
        keys = np.stack([rows.sample, rows.path], axis=1)
        assert np.unique(keys, axis=0).shape[0] == len(rows)
    u = tiled.uniforms("x", 2, 3)
    assert u.shape == (6, 2, 3)
    np.testing.assert_array_equal(tiled.take(np.array([4])).uniforms("x", 2, 3), u[4:5])
    assert not np.array_equal(u[0], u[3])  # the two copies of a sample draw different numbers


def test06_sequential_streams_are_reproducible_and_named():
    a = stream(4, "samples", 2).random(5)
    np.testing.assert_array_equal(a, stream(4, "samples", 2).random(5))
    assert not np.array_equal(a, stream(4, "kernel", 2).random(5))
    with pytest.raises(ValueError, match="seed"):
        stream(-1, "samples")
