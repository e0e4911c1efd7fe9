r"""Refuse requests that cannot fit in memory or finish in reasonable time, before any work starts.

Renderers work through their samples in memory chunks (``CHUNK`` samples at a time,
random numbers drawn per chunk), so memory does not grow with the sample count; it
grows with the number of pixels (per-batch images are kept) and with the rays each
sample traces (probes). A request for 10⁹ pixels, 2⁴⁰ samples per pixel or 10⁶
probes would end in a ``MemoryError`` or run for days; :func:`check_request` turns it
into one :class:`~flatland.core.validate.ValidationError` that names the field and
states the estimate.

What a method allocates beyond its rays comes from the method's own memory model, one
function next to the code that allocates (sphere3d: the ``memory_model`` of each method
module), as terms (:class:`Term`): bytes held at once whatever the chunk (a table of one
sample's probe pairs, a block of edge samples bounded by a ceiling), rays per sample,
and rays in all. The estimate of a request is

    $M = P B b_\mathrm{pix} + S (r + Σ_t r_t) b_\mathrm{ray} + Σ_t a_t$,

P pixels, B batches, $b_\mathrm{pix}$ held bytes per pixel and batch, S the samples a
chunk holds, r the base rays per sample, $r_t$ and $a_t$ each term's rays per sample and
bytes at once, $b_\mathrm{ray}$ = :data:`BYTES_PER_RAY`; the error names the field of
the largest part. Rays in all: $P N (r + Σ_t r_t) + Σ_t R_t$ (N samples per pixel, $R_t$ a
term's rays in all).
One memory chunk per request: threads running chunks side by side are not counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from flatland.core.validate import ValidationError

__all__ = [
    "BYTES_PER_RAY",
    "IMAGE_BYTES_PER_PIXEL",
    "MEMORY_LIMIT",
    "RAY_LIMIT",
    "Request",
    "Term",
    "check_request",
    "memory_estimate",
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
class Term:
    """What one option of a method adds to a request (the method's memory model).

    ``field`` and ``value`` name the option in the error; ``what`` says what the value counts
    (``"probes per kernel"``) and ``block`` what ``at_once`` holds (``"one row's probe pairs"``).
    ``at_once``: bytes held at once whatever the chunk, ``sample_rays``: rays per sample (memory in
    the chunk, :data:`BYTES_PER_RAY` each, and time), ``rays``: rays in all, not per sample.
    """

    field: str
    value: Any
    what: str
    block: str = ""
    at_once: float = 0.0
    sample_rays: float = 0.0
    rays: float = 0.0


@dataclass(frozen=True)
class Request:
    """What a render call will do: ``pixels`` × ``spp`` samples in ``batches``, ``rays`` per sample.

    ``chunk`` is the number of samples held in memory at once; ``*_field`` name the
    user's inputs the error should point at. ``pixel_bytes``: bytes held per pixel and batch
    until the image is made (the images, and a film's buffers); ``terms``: the method's options
    (:class:`Term`).
    """

    pixels: int
    spp: int
    batches: int
    rays: int
    chunk: int
    pixels_field: str = "camera.pixels"
    spp_field: str = "spp"
    rays_field: str = "probes"
    pixel_bytes: float = IMAGE_BYTES_PER_PIXEL
    terms: tuple[Term, ...] = ()
    chunk_field: str = ""
    """The field that makes a chunk hold more samples than usual (``spp``, when one pixel's samples
    are more than a chunk's), named for the chunk's rays instead of the options behind them."""


def _size(nbytes: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes:.0f} bytes"


def _memory_parts(r: Request) -> list[tuple[float, str, str]]:
    """The memory estimate's parts: (bytes, the field it grows with, what it is)."""
    held = min(r.chunk, r.pixels * r.spp)
    images = float(r.pixels) * r.batches * r.pixel_bytes
    chunk = float(held) * r.rays * BYTES_PER_RAY
    per_chunk = f"{held} samples per memory chunk need about"
    field = r.chunk_field or (r.rays_field if r.rays > 3 else r.spp_field)
    film = (
        f" and film ({r.pixel_bytes:g} bytes per pixel and batch)"
        if r.pixel_bytes > IMAGE_BYTES_PER_PIXEL
        else ""
    )
    parts = [
        (images, r.pixels_field, f"{r.pixels} pixels × {r.batches} batches need about {_size(images)} for "
         f"the per-batch images{film}"),
        (chunk, field, f"{r.rays} rays per sample × {per_chunk} {_size(chunk)}"),
    ]  # fmt: skip
    for t in r.terms:
        option = f"{t.field}={t.value} ({t.what})"
        traced = float(held) * t.sample_rays * BYTES_PER_RAY
        if traced:
            text = f"{option}: {t.sample_rays:g} rays per sample × {per_chunk} {_size(traced)}"
            parts.append((traced, r.chunk_field or t.field, text))
        if t.at_once:
            parts.append((t.at_once, t.field, f"{option}: {t.block} need about {_size(t.at_once)} at once"))
    return parts


def _ray_parts(r: Request) -> list[tuple[float, str, str]]:
    """The rays in all, by part: (rays, the field they grow with, what they are)."""
    samples = float(r.pixels) * r.spp
    parts = [
        (samples * r.rays, r.spp_field, f"{r.spp} samples × {r.pixels} pixels × {r.rays} rays per sample")
    ]
    for t in r.terms:
        if t.sample_rays or t.rays:
            mine = samples * t.sample_rays + t.rays
            parts.append((mine, t.field, f"{t.field}={t.value} ({t.what}) adds {mine:.2g} rays"))
    return parts


def memory_estimate(r: Request) -> float:
    """The bytes ``r`` is estimated to need at once: the sum M of the module docstring."""
    return sum(p[0] for p in _memory_parts(r))


def check_request(r: Request) -> None:
    """Raise a ValidationError when ``r`` needs more than :data:`MEMORY_LIMIT` or :data:`RAY_LIMIT`.

    Each estimate is the sum of its parts (module docstring); the error names the field of the
    largest part and states it, and the sum.
    """
    parts = _memory_parts(r)
    total = memory_estimate(r)
    if total > MEMORY_LIMIT:
        largest, field, text = max(parts, key=lambda p: p[0])
        rest = f" ({_size(total)} in all)" if total > 1.01 * largest else ""
        raise ValidationError(field, f"{text}{rest}, more than the {_size(MEMORY_LIMIT)} a request may use")
    parts = _ray_parts(r)
    rays = sum(p[0] for p in parts)
    if rays > RAY_LIMIT:
        _, field, text = max(parts, key=lambda p: p[0])
        raise ValidationError(
            field,
            f"{text}: {rays:.2g} rays in all, more than the {RAY_LIMIT:.2g} (2^36) a request may trace "
            "(days of work)",
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
