"""Reproducible, named random streams.

Every estimator draws each kind of random number from its own stream, keyed by the
user's seed and a stream name (``"samples"``, ``"kernel"``, ``"probes"``, ...). Two
methods that share a stream name see the same numbers for the same seed, whatever
else they draw: that is what keeps the reparameterized primal estimate bit-identical
to the naive one (DESIGN 2.5), and what common random numbers in finite differences
rely on.
"""

from __future__ import annotations

import zlib

import numpy as np

from flatland.core.validate import check_seed

__all__ = ["stream"]


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
