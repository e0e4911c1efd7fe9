"""Random streams: sequential per name, and counter-based draws keyed on sample indices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from flatland.core.rng import Draws, keyed_bits, keyed_normals, keyed_uniforms, philox4x64, stream
from flatland.core.stats import chi2_gof, sidak

ALPHA = 1e-3
GOF_TESTS = 2  # chi-square tests in this file, for the Šidák correction
BINS = 41


def test01_philox_matches_numpys_bit_for_bit():
    # numpy's Philox increments its 256-bit counter before each block: block 0 is philox(counter + 1)
    rng = np.random.default_rng(5)
    for _ in range(20):
        counter = rng.integers(0, 2**63, size=4, dtype=np.uint64)
        key = rng.integers(0, 2**63, size=2, dtype=np.uint64)
        expected = np.random.Philox(counter=counter, key=key).random_raw(4)
        bumped = counter.copy()
        bumped[0] += np.uint64(1)  # no carry: counter[0] < 2^63
        got = philox4x64(bumped[None, :], (int(key[0]), int(key[1])))[0]
        np.testing.assert_array_equal(got, expected)


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
