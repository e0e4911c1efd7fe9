"""Reproducible, named random streams.

Every estimator draws each kind of random number from its own stream, keyed by the
user's seed and a stream name (``"samples"``, ``"kernel"``, ``"probes"``, ...). Two
methods that share a stream name see the same numbers for the same seed, whatever
else they draw: that is what keeps the reparameterized primal estimate bit-identical
to the naive one (DESIGN 2.5), and what common random numbers in finite differences
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

__all__ = ["Draws", "keyed_bits", "keyed_normals", "keyed_uniforms", "philox4x64", "stream"]


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
_M0, _M1 = np.uint64(0xD2E7470EE14C6C93), np.uint64(0xCA5A826395121157)  # Philox4x64 multipliers
_W0, _W1 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBB67AE8584CAA73B)  # Weyl key increments
_LOW = np.uint64(0xFFFFFFFF)
_32 = np.uint64(32)
ROUNDS = 10


def _mulhilo(a: np.uint64, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """High and low 64-bit words of the 128-bit products ``a * b`` (schoolbook on 32-bit halves)."""
    a0, a1 = a & _LOW, a >> _32
    b0, b1 = b & _LOW, b >> _32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1  # each exact: < 2^64
    mid = (p00 >> _32) + (p01 & _LOW) + (p10 & _LOW)  # < 3 * 2^32: no overflow
    hi = p11 + (p01 >> _32) + (p10 >> _32) + (mid >> _32)
    return hi, a * b  # the low word wraps modulo 2^64, as it should


def philox4x64(counter: np.ndarray, key: tuple[int, int]) -> np.ndarray:
    """The Philox4x64-10 block function (Salmon et al. 2011) on counters of shape (n, 4): (n, 4) uint64.

    The same function numpy's :class:`numpy.random.Philox` applies to its counter
    (a test checks the two agree bit for bit); here it runs on many counters at
    once, which is what makes draws keyed on sample indices cheap.
    """
    x = [np.array(counter[:, i], dtype=np.uint64) for i in range(4)]
    k0, k1 = np.uint64(key[0]), np.uint64(key[1])
    with np.errstate(over="ignore"):
        for r in range(ROUNDS):
            if r:
                k0, k1 = k0 + _W0, k1 + _W1  # key schedule: Weyl sequence
            hi0, lo0 = _mulhilo(_M0, x[0])
            hi1, lo1 = _mulhilo(_M1, x[2])
            x = [hi1 ^ x[1] ^ k0, lo1, hi0 ^ x[3] ^ k1, lo0]
    return np.stack(x, axis=1)


def _key(seed: int, name: str) -> tuple[int, int]:
    return check_seed("seed", seed), zlib.crc32(name.encode("utf-8"))


def keyed_bits(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """``count`` random 64-bit words per row of ``keys``: a pure function of (seed, name, key, column).

    Parameters
    ----------
    seed : int
        The user's seed.
    name : str
        Stream name (one per call site: ``"kernel.center"``, ``"probes.film"``, ...).
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
    n, width = keys.shape
    if width > 2:
        raise ValueError(f"keys: at most 2 words per row, got {width}")
    blocks = -(-count // 4)
    counter = np.zeros((n, blocks, 4), dtype=np.uint64)
    counter[:, :, 0] = keys[:, :1].astype(np.uint64)
    if width == 2:
        counter[:, :, 1] = keys[:, 1:].astype(np.uint64)
    counter[:, :, 2] = np.arange(blocks, dtype=np.uint64)
    return philox4x64(counter.reshape(-1, 4), _key(seed, name)).reshape(n, 4 * blocks)[:, :count]


def keyed_uniforms(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """Uniforms in [0, 1), shape (n, count), keyed like :func:`keyed_bits` (53 random bits each)."""
    return (keyed_bits(seed, name, keys, count) >> np.uint64(11)) * 2.0**-53


def keyed_normals(seed: int, name: str, keys: np.ndarray, count: int) -> np.ndarray:
    """Standard normals, shape (n, count), keyed like :func:`keyed_bits` (inverse CDF of (k + 1/2) / 2^53)."""
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
