"""Reproducible, named random streams.

Every estimator draws each kind of random number from its own stream, keyed by the
user's seed and a stream name (``"samples"``, ``"kernel"``, ``"probes"``, ...). Two
methods that share a stream name see the same numbers for the same seed, whatever
else they draw: that is what keeps the reparameterized primal estimate bit-identical
to the naive one (Loubet et al. 2019, Sec. 3.2), and what common random numbers in finite differences
rely on.

Two kinds of stream. :func:`stream` is a sequential generator for draws that belong
to no sample (a pixel's rotation, a boundary method's edge samples per batch).
:func:`keyed_uniforms` / :func:`keyed_normals` are counter-based: the numbers of a
row are a function of ``(seed, name, key)`` alone, the key being the global index of
the primary sample the row belongs to. Renderers draw every per-sample number this
way, so an image does not depend on how its samples were split into memory chunks
or batches of work, and memory is bounded by the chunk (numbers are made where they
are used, chunk by chunk).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
from scipy import special

from flatland.core.validate import check_seed

__all__ = ["Draws", "keyed_bits", "keyed_normals", "keyed_uniforms", "mix64", "stream"]


def stream(seed: int, name: str, *extra: int) -> np.random.Generator:
    """A generator for the stream ``name`` of ``seed`` (``extra`` keys sub-streams, e.g. batches).

    Parameters
    ----------
    seed : int
        The user's seed, a non-negative integer.
    name : str
        Stream name; streams with different names are statistically independent.
    *extra : int
        Further non-negative keys (batch index, pixel block, ...).

    Returns
    -------
    numpy.random.Generator
        A PCG64 generator that depends only on ``(seed, name, *extra)``.
    """
    seed = check_seed("seed", seed)
    key = (zlib.crc32(name.encode("utf-8")), *(int(e) for e in extra))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=key)))


# ------------------------------------------------------------------ counter-based draws keyed on samples
_GAMMA = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64's Weyl increment, 2^64 / golden ratio
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_C1, _C2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's output function (Steele, Lea, Flood 2014; Vigna's constants), elementwise on uint64.

    A bijection of 64-bit words with full avalanche. ``mix64(k * GAMMA)`` for
    k = 1, 2, ... is the SplitMix64 sequence of seed 0 (a test checks its first words).
    """
    with np.errstate(over="ignore"):
        z = z ^ (z >> _S30)  # a new array: the input is left alone; the steps below work in place
        z *= _C1
        z ^= z >> _S27
        z *= _C2
        z ^= z >> _S31
        return z


def _key(seed: int, name: str) -> np.uint64:
    """One 64-bit key for the stream ``name`` of ``seed``."""
    seed = check_seed("seed", seed)
    words = np.array([seed & 0xFFFFFFFFFFFFFFFF, zlib.crc32(name.encode("utf-8"))], dtype=np.uint64)
    with np.errstate(over="ignore"):
        return mix64(mix64(words[0] + _GAMMA) ^ (words[1] * _GAMMA))


def keyed_bits(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """``count`` random 64-bit words per row of ``keys``: a pure function of (seed, name, key, column).

    Row i's words are the SplitMix64 sequence seeded with a hash of ``(seed, name,
    keys[i])``: ``h = mix64(mix64(key(seed, name) + sample) + (path + 1) * GAMMA)``, then
    word j is ``mix64(h + (j + 1) * GAMMA)``. About a dozen integer operations per word,
    vectorized over all rows.

    Parameters
    ----------
    seed : int
        The user's seed.
    name : str
        Stream name (one per call site: ``"kernel.film"``, ``"probes.emitter"``, ...).
    keys : ndarray of int, shape (n,) or (n, 2)
        One key per row: the global index of the primary sample the row belongs to,
        and optionally a second word telling apart rows of the same sample (a pair
        member, an MIS technique).
    count : int
        Words per row.

    Returns
    -------
    ndarray of uint64, shape (n, count)
        Row i depends only on ``(seed, name, keys[i])``: not on the other rows, their
        order, or how the samples were split into chunks.
    """
    keys = np.asarray(keys)
    keys = keys.reshape(-1, 1) if keys.ndim == 1 else keys
    if keys.shape[1] > 2:
        raise ValueError(f"keys: at most 2 words per row, got {keys.shape[1]}")
    sample = keys[:, 0].astype(np.uint64)
    path = keys[:, 1].astype(np.uint64) if keys.shape[1] == 2 else np.zeros_like(sample)
    j = np.arange(1, count + 1, dtype=np.uint64)
    with np.errstate(over="ignore"):
        h = mix64(mix64(_key(seed, name) + sample) + (path + np.uint64(1)) * _GAMMA)
        return mix64(h[:, None] + j[None, :] * _GAMMA)


def keyed_uniforms(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """Uniforms in [0, 1), shape (n, count), keyed like :func:`keyed_bits` (53 random bits each)."""
    return (keyed_bits(seed, name, keys, count) >> np.uint64(11)) * 2.0**-53


def keyed_normals(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """Standard normals, shape (n, count), keyed like :func:`keyed_bits` (inverse CDF of
    $(k + 1/2) / 2^{53}$).
    """
    u = ((keyed_bits(seed, name, keys, count) >> np.uint64(11)) + 0.5) * 2.0**-53  # in (0, 1): finite
    return special.ndtri(u)


@dataclass(frozen=True)
class Draws:
    """Per-row random numbers keyed on the primary sample each row belongs to.

    ``sample[i]`` is the global index of row i's primary sample (pixel-major:
    ``pixel * spp + j``), ``path[i]`` tells apart the rows of one sample (pair
    members, MIS techniques). Every draw is :func:`keyed_uniforms` of
    ``(seed, name, (sample, path))``: a call site names its own stream, and the
    numbers a sample sees do not depend on which other samples share its chunk.
    :meth:`take`, :meth:`tile` and :meth:`repeat` follow the row operations of the
    arrays they describe (``x[rows]``, ``np.tile``, ``np.repeat``).
    """

    seed: int
    sample: np.ndarray
    path: np.ndarray

    @classmethod
    def of(cls, seed: int, sample: np.ndarray) -> Draws:
        """One row per primary sample (path 0)."""
        sample = np.asarray(sample, dtype=np.int64)
        return cls(check_seed("seed", seed), sample, np.zeros_like(sample))

    def __len__(self) -> int:
        return self.sample.size

    def _keys(self) -> np.ndarray:
        return np.stack([self.sample, self.path], axis=1)

    def uniforms(self, name: str, *shape: int) -> np.ndarray:
        """Uniforms in [0, 1) of shape ``(len(self), *shape)`` from the stream ``name``."""
        count = int(np.prod(shape, dtype=np.int64))
        return keyed_uniforms(self.seed, name, self._keys(), count).reshape(len(self), *shape)

    def normals(self, name: str, *shape: int) -> np.ndarray:
        """Standard normals of shape ``(len(self), *shape)`` from the stream ``name``."""
        count = int(np.prod(shape, dtype=np.int64))
        return keyed_normals(self.seed, name, self._keys(), count).reshape(len(self), *shape)

    def take(self, rows: np.ndarray) -> Draws:
        """The rows ``rows`` (an index or boolean mask), keys unchanged."""
        return Draws(self.seed, self.sample[rows], self.path[rows])

    def tile(self, ways: int) -> Draws:
        """All rows ``ways`` times over (``np.tile``): copy k gets path ``path * ways + k``."""
        k = np.repeat(np.arange(ways, dtype=np.int64), len(self))
        return Draws(self.seed, np.tile(self.sample, ways), np.tile(self.path, ways) * ways + k)

    def repeat(self, ways: int) -> Draws:
        """Each row ``ways`` times in a row (``np.repeat``): copy k gets path ``path * ways + k``."""
        k = np.tile(np.arange(ways, dtype=np.int64), len(self))
        return Draws(self.seed, np.repeat(self.sample, ways), np.repeat(self.path, ways) * ways + k)
