"""Refuse requests that cannot fit in memory or finish in reasonable time, before any work starts.

Renderers work through their samples in memory chunks (``CHUNK`` samples at a time,
random numbers drawn per chunk), so memory does not grow with the sample count; it
grows with the number of pixels (per-batch images are kept) and with the rays each
sample traces (probes). A request for 10⁹ pixels, 2⁴⁰ samples per pixel or 10⁶
probes would end in a ``MemoryError`` or run for days; :func:`check_request` turns it
into one :class:`~flatland.core.validate.ValidationError` that names the field and
states the estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

from flatland.core.validate import ValidationError

__all__ = [
    "BYTES_PER_RAY",
    "IMAGE_BYTES_PER_PIXEL",
    "MEMORY_LIMIT",
    "RAY_LIMIT",
    "Request",
    "check_request",
    "rays_per_sample",
]

MEMORY_LIMIT = 8 * 2**30
"""Bytes one request may plan for (the machines this is written for have 24 GiB)."""
RAY_LIMIT = 2**36
"""Rays one request may trace: about 7e10, many hours at the renderers' few million rays per second."""
BYTES_PER_RAY = 1024
"""Working memory per estimated ray of a chunk: origins, directions, hits and their tangents
(peak measured with tracemalloc on both shadow scenes, naive and reparam: 84 to 961 bytes)."""
IMAGE_BYTES_PER_PIXEL = 64
"""Per batch and pixel: value and derivative sums, means and standard errors (8 float64)."""


@dataclass(frozen=True)
class Request:
    """What a render call will do: ``pixels`` × ``spp`` samples in ``batches``, ``rays`` per sample.

    ``chunk`` is the number of samples held in memory at once; ``*_field`` name the
    user's inputs the error should point at.
    """

    pixels: int
    spp: int
    batches: int
    rays: int
    chunk: int
    pixels_field: str = "camera.pixels"
    spp_field: str = "spp"
    rays_field: str = "probes"


def _size(nbytes: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes:.0f} bytes"


def check_request(r: Request) -> None:
    """Raise a ValidationError when ``r`` needs more than :data:`MEMORY_LIMIT` or :data:`RAY_LIMIT`."""
    images = float(r.pixels) * r.batches * IMAGE_BYTES_PER_PIXEL
    if images > MEMORY_LIMIT:
        raise ValidationError(
            r.pixels_field,
            f"{r.pixels} pixels × {r.batches} batches need about {_size(images)} for the per-batch images, "
            f"more than the {_size(MEMORY_LIMIT)} a request may use",
        )
    held = min(r.chunk, r.pixels * r.spp)
    chunk = float(held) * r.rays * BYTES_PER_RAY
    if chunk > MEMORY_LIMIT:
        raise ValidationError(
            r.rays_field if r.rays > 3 else r.spp_field,
            f"{r.rays} rays per sample × {held} samples per memory chunk need about "
            f"{_size(chunk)}, more than the {_size(MEMORY_LIMIT)} a request may use",
        )
    rays = float(r.pixels) * r.spp * r.rays
    if rays > RAY_LIMIT:
        raise ValidationError(
            r.spp_field,
            f"{r.spp} samples × {r.pixels} pixels × {r.rays} rays per sample = {rays:.2g} rays, more than "
            f"the {RAY_LIMIT:.2g} (2^36) a request may trace (days of work)",
        )


def rays_per_sample(options: dict) -> int:
    """An upper estimate of the rays one camera sample traces under a method's resolved ``options``.

    A camera ray and two shading rays (MIS), and for a reparameterization each of them
    with its probes, twice over for paired samples; finite differences render twice. A ``probes``
    of None (the method's own default, a few) counts as 8.
    """
    probes = options.get("probes", 0)
    probes = 8 if probes is None and "probes" in options else int(probes or 0)
    rays = 3 * (1 + probes) * (2 if options.get("paired") or options.get("variant") == "paper" else 1)
    return rays * (2 if "h" in options else 1)
