"""What a method estimates: the pixels of an image, or the irradiance at one point, in independent batches.

A task fixes the scene, the parameter, the sample count, the seed and the batches;
``task.evaluate(theta, transforms)`` runs the integrator once with θ given as a
float (plain) or as a Dual, and returns a :class:`Tally` of per-batch means. Methods
(:mod:`sphere3d.methods`) differ only in the ``theta`` and the
:class:`~sphere3d.integrator.Transforms` they pass, so they share every primary
sample: sample j of pixel p has the global index ``p * spp + j`` (batch
``j // (spp / batches)``), its uniforms are ``Draws.of(seed, index).uniforms("samples", ...)``
whatever the method, and anything a method draws in addition is keyed on the same
index under other stream names (``"kernel.film"``, ``"kernel.bsdf"``, ``"probes.emitter"``,
...; see :class:`flatland.core.rng.Draws`). Results therefore do not depend on
:data:`CHUNK` or on the number of threads (:mod:`sphere3d.execution`), nor on which machines of a
Dask cluster compute which tiles of chunks (:meth:`ImageTask._on_cluster`, :meth:`PointTask._on_cluster`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core import progress
from flatland.core.budget import IMAGE_BYTES_PER_PIXEL, Term
from flatland.core.dual import Dual, detach, k_of, tangent, variable, variables
from flatland.core.rng import Draws
from flatland.core.translation import control_variate
from flatland.core.validate import check_choice
from sphere3d import execution
from sphere3d.film import FILMS, gather, reach, splat_band, splat_stencils, splat_weights
from sphere3d.integrator import (
    PRIMARY_UNIFORMS,
    Identity,
    PixelSamples,
    Shading,
    Transforms,
    pixel_samples,
)
from sphere3d.paths import irradiance_paths, vertex
from sphere3d.scene import Scene
from sphere3d.state import build_state

__all__ = ["CHUNK", "TILE_BYTES", "ImageTask", "PointTask", "Tally"]

CHUNK = 1 << 15
"""Camera samples per memory chunk (a loop over chunks, vectorized inside); results do not
depend on it (every draw is keyed on the sample's index)."""
TILE_BYTES = 128 << 20
"""Bytes of the splat film's stencils per tile of memory chunks (:meth:`ImageTask._splat_tiles`): with
the rows a tile's neighbours still need, the film's working set, whatever the image's height
(:meth:`ImageTask.film_terms`). Results do not depend on it."""
CV_SCOPES = ("pixel", "batch", "off")
"""Whose radiance scales a sample's filter-weight control variate (:meth:`ImageTask._control_variate`)."""


@dataclass(frozen=True)
class Tally:
    """Per-batch means of the value and of its θ-derivative, shape (batches, ``*output_shape``); for k
    parameters the derivative has a leading axis of k, (k, batches, ``*output_shape``)."""

    value: np.ndarray
    derivative: np.ndarray


def _tally(values: list[Any], shape: tuple[int, ...]) -> Tally:
    k = k_of(*values)
    full = shape if k is None else (k, *shape)
    deriv = np.stack(
        [np.asarray(tangent(v), dtype=np.float64).reshape(full) for v in values], axis=-len(shape) - 1
    )
    value = np.stack([np.asarray(detach(v), dtype=np.float64).reshape(shape) for v in values])
    return Tally(value=value, derivative=deriv)


class _Parameters:
    """What a task's ``param`` holds: one name (str), None, or a tuple of k names (k tangents)."""

    param: str | tuple[str, ...] | None

    @property
    def k(self) -> int | None:
        """The number of parameters of a tuple ``param``; None for one parameter (or none)."""
        return len(self.param) if isinstance(self.param, tuple) else None

    def dual_offset(self) -> Any:
        """The offset θ0 = 0 as forward-mode seed(s): ``variable(0.0)``, or for k parameters
        ``variables(k)`` (parameter i with the unit tangent e_i, :mod:`flatland.core.dual`)."""
        return variables(self.k) if self.k is not None else variable(0.0)

    def parameters(self) -> tuple[str, ...]:
        """The parameters, as a tuple (one for a single parameter)."""
        return self.param if isinstance(self.param, tuple) else () if self.param is None else (self.param,)


@dataclass(frozen=True)
class ImageTask(_Parameters):
    """The pixel integrals of ``scene``'s camera image: ``spp`` samples per pixel in ``batches``.

    ``cv_scope``: :meth:`_control_variate`; ``film``: ``"splat"`` (default) or ``"pixel"``
    (:mod:`sphere3d.film`, :meth:`_splat_chunk`), for every method alike.
    """

    scene: Scene
    param: str | tuple[str, ...] | None
    spp: int
    seed: int
    batches: int
    tracer: str = "embree"
    cv_scope: str = "pixel"
    film: str = "splat"
    """``"splat"`` (default): each sample in every pixel its filter covers, weighted by
    $k(s - p) / Σ_{p'} p(s - p')$ (:mod:`sphere3d.film`); ``"pixel"``: in the pixel that drew it."""
    max_depth: int = 1
    """Vertices per path (:mod:`sphere3d.paths`); 1: direct illumination."""

    @property
    def shape(self) -> tuple[int, int]:
        return (self.scene.camera.height, self.scene.camera.width)

    def __post_init__(self) -> None:
        check_choice("cv_scope", self.cv_scope, CV_SCOPES)
        check_choice("film", self.film, FILMS)

    def _cv_samples(self, batches: int, per_batch: int) -> int:
        """Samples per scope of the control variate's scale (all of a pixel's, or one batch's), 0 where
        it is off: ``cv_scope="off"``, one sample per scope, or the box filter (:meth:`_control_variate`)."""
        n = batches * per_batch if self.cv_scope == "pixel" else per_batch
        return 0 if self.cv_scope == "off" or n < 2 or self.scene.camera.filter == "box" else n

    def _leave_one_out(self, radiance: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Radiance totals per pixel (and batch) of ``radiance`` (batches, pixels, samples), broadcastable
        to it, and each sample's scale: the mean of the other ``n - 1`` samples of its scope."""
        pooled = self.cv_scope == "pixel"
        # each pixel's sum over one contiguous row (batch-major), so it does not depend on the chunk's layout
        rows = radiance.transpose(1, 0, 2).reshape(radiance.shape[1], -1) if pooled else radiance
        total = np.sum(np.ascontiguousarray(rows), axis=-1)
        total = total[None, :, None] if pooled else total[..., None]
        return total, (total - radiance) / (n - 1)  # leave sample i out

    def _control_variate(self, samples: PixelSamples, batches: int, per_batch: int) -> Any:
        r"""Per-sample estimates (batches × pixels × samples) with the filter-weight control variate.

        With a continuous filter, the tangent of each sample's filter weight $w_i$ has
        zero mean given its pixel's rotation ($∫ k = 1$ for every θ; Loubet et al. 2019,
        Sec. 4.2, theory/kernels), so $e_i - c_{-i} (w_i - \mathrm{detach}(w_i))$ keeps the
        expectation of every batch mean, value and derivative, while cancelling the term
        $L \dot w_i$ that a rotated pixel integral adds even where the radiance is flat. The
        value is untouched, bit for bit (an exact zero is subtracted). Not applied to the
        box filter, whose weight derivative does not have zero mean (theory/pixel_filters).

        The scale $c_{-i}$ is the mean radiance (primal) of the pixel's *other*
        samples, ``cv_scope="pixel"`` (default): all ``spp - 1`` of them, in every
        batch. It is a function of samples independent of sample i (its own rotation
        included: each sample's film kernel and rotation come from its own streams, and
        the radiance's value does not depend on them), and $\dot w_i$ has zero mean given
        everything else, so every batch mean stays unbiased. ``"batch"`` takes the other samples
        of the same batch only: with one sample per batch (16 spp in 16 batches) it has none and
        the control variate is off; ``"off"`` never applies it (both for comparison).

        Batches are then weakly correlated: batch b's term $c_{-i} \dot w_i$ holds the radiance of batch b'
        and vice versa. With $γ = \mathrm{Cov}(L, \dot w)$ (zero where the radiance is flat) and
        $N = \mathrm{spp}$, $\mathrm{Cov}(D_b, D_{b'}) = γ^2 / (N - 1)^2$ for the derivative's batch means
        $D_b$ (every other cross term has zero mean: $\dot w_i$ is centred given the rest), against
        $\mathrm{Var}\, D_b = σ^2 / n$ ($n = N / \mathrm{batches}$, $σ^2$ the controlled per-sample variance,
        usually of the order of $E[((L - E L) \dot w)^2] ≥ γ^2$). The batch spread thus understates the
        variance of the image by a relative $(\mathrm{batches} - 1) n γ^2 / ((N - 1)^2 σ^2) ≈ γ^2 / (σ^2 N)$,
        at most about $1 / N$. The pooled scale also has less noise of its own than a batch's (N - 1
        samples instead of n - 1), which matters most at few samples per batch.
        """
        est = samples.estimate.reshape(batches, -1, per_batch)
        n = self._cv_samples(batches, per_batch)
        if not isinstance(est, Dual) or not n:
            return est.reshape(-1, per_batch)
        radiance = np.asarray(detach(samples.radiance), dtype=np.float64).reshape(batches, -1, per_batch)
        _, others = self._leave_one_out(radiance, n)
        weight = samples.weight.reshape(batches, -1, per_batch)
        return control_variate(est, others, weight).reshape(-1, per_batch)

    def evaluate(self, theta: Any, transforms: Transforms | None = None) -> Tally:
        """Render every pixel with the parameter offset by ``theta`` (float or Dual) under ``transforms``.

        All batches of a range of pixels are processed together (one vectorized call
        per memory chunk); every sample's numbers, its camera rotation's included, are
        keyed on its index ``pixel * spp + j``, so every batch is independent and the
        image does not depend on how pixels are grouped into chunks, nor the splat film's
        chunks into tiles (:meth:`_splat_tiles`). Inside :func:`sphere3d.execution.cluster` the
        chunks run on a Dask cluster (:meth:`_on_cluster`).
        """
        transforms = transforms or Identity()
        if execution.client() is not None:
            return self._on_cluster(theta, transforms)
        state = build_state(self.scene, self.param, theta, self.tracer)
        # the method's per-state tables, built at once, and its per-image term's batches beside them
        jobs = getattr(transforms, "pixel_terms", lambda *_: ())(self, state)
        terms = execution.prepare(transforms, state, jobs)
        batches, per_batch = self.batches, self.spp // self.batches
        chunk = functools.partial(self._chunk, state, transforms)
        chunks = range(self._chunk_count())
        if self.film == "splat":
            tally = self._splat_tiles(chunk, chunks, batches, per_batch, state.k)
        else:
            parts = execution.map_chunks(chunk, chunks)
            tally = _tally(list(np.concatenate(parts, axis=1)), self.shape)
        # a method's derivative-only term per batch and pixel: its jobs' results, or its own pass
        stacked = np.stack(terms, axis=0 if state.k is None else 1) if jobs else None
        extra = stacked if jobs else transforms.pixel_extra(self, state)
        return tally if extra is None else Tally(tally.value, tally.derivative + extra)

    def _chunk_count(self) -> int:
        """The image's memory chunks (:attr:`chunk_pixels` pixels each, the last one fewer)."""
        return -(-self.shape[0] * self.shape[1] // self.chunk_pixels)

    def _chunk(
        self,
        state: Any,
        transforms: Transforms,
        c: int,
        out: tuple | None = None,
        offset: int = 0,
        chunk_pixels: int | None = None,
    ) -> np.ndarray | None:
        """Memory chunk c's samples: their per-batch means (pixel film), or their stencils written to
        ``out``, whose first column is pixel ``offset`` (splat film). Chunks of ``chunk_pixels`` pixels
        (default :attr:`chunk_pixels`: a worker of a cluster is given its client's)."""
        height, width = self.shape
        batches, per_batch = self.batches, self.spp // self.batches
        size = chunk_pixels or self.chunk_pixels
        pix = np.arange(c * size, min(height * width, (c + 1) * size))
        # sample order: batch, pixel, sample; sample s of batch b is its pixel's j = b * per_batch + s
        b_idx, p_idx, s_idx = np.meshgrid(np.arange(batches), pix, np.arange(per_batch), indexing="ij")
        draws = Draws.of(self.seed, (p_idx * self.spp + b_idx * per_batch + s_idx).ravel())
        u = draws.uniforms("samples", PRIMARY_UNIFORMS)
        rows, cols = np.divmod(p_idx.ravel(), width)
        if out is not None:
            kind = self.scene.camera.filter
            reach_of = lambda x, y: splat_weights(x, y, rows, cols, width, height, kind)  # noqa: E731
            est = pixel_samples(
                state, transforms, rows, cols, u, draws, reach_of, vertex(self.max_depth, state)
            )
            self._splat_chunk(est, pix, batches, per_batch, out, offset)
            return None
        est = pixel_samples(state, transforms, rows, cols, u, draws, vertex=vertex(self.max_depth, state))
        return np.mean(self._control_variate(est, batches, per_batch), axis=1).reshape(batches, pix.size)

    def _chunk_range(
        self, state: Any, transforms: Transforms, first: int, stop: int, chunk_pixels: int
    ) -> Any:
        """Memory chunks ``first`` to ``stop`` (exclusive) of ``chunk_pixels`` pixels, on this machine's
        threads: their per-batch means (pixel film), or the stencils of their pixels (splat film,
        :meth:`_splat_buffers`)."""
        chunk = functools.partial(self._chunk, state, transforms, chunk_pixels=chunk_pixels)
        if self.film != "splat":
            return execution.map_chunks(chunk, range(first, stop), counted=False)
        pixels = self.shape[0] * self.shape[1]
        lo, hi = first * chunk_pixels, min(pixels, stop * chunk_pixels)
        out = self._splat_buffers(hi - lo, state.k)
        execution.map_chunks(functools.partial(chunk, out=out, offset=lo), range(first, stop), counted=False)
        return out

    def _on_cluster(self, theta: Any, transforms: Transforms) -> Tally:
        """:meth:`evaluate`'s chunks as tiles on the Dask cluster of :func:`~sphere3d.execution.client`.

        The memory chunks are this process's (:attr:`chunk_pixels`); a tile is a run of whole chunks
        (:func:`~sphere3d.execution.tile_ranges`), computed on a worker by :meth:`_chunk_range`
        from the pickled task, θ and transforms, the worker building its own scene state and tracer.
        Each chunk thus computes the same numbers as in a local run; the tiles' stencils fill the
        columns of one buffer for the whole image, from which :meth:`_splat_rows` makes every row by
        the same sums in the same order as a local run: the image is bit for bit the local one (the
        client holds the whole image's stencils, :meth:`film_terms` of a one-tile image). The
        per-image term (``pixel_extra``) is one more task.
        """
        height, width = self.shape
        batches, per_batch = self.batches, self.spp // self.batches
        items = execution.tile_ranges(self._chunk_count())
        results = execution.map_tiles(_remote, (self, theta, transforms, self.chunk_pixels), [*items, None])
        extra, results = results[-1], results[:-1]
        if self.film != "splat":
            tally = _tally(list(np.concatenate([p for parts in results for p in parts], axis=1)), self.shape)
        else:
            k = theta.k if isinstance(theta, Dual) else None
            out = self._splat_buffers(height * width, k)
            for (first, stop), tile in zip(items, results, strict=True):
                lo, hi = first * self.chunk_pixels, min(height * width, stop * self.chunk_pixels)
                for whole, part in zip(out, tile, strict=True):
                    if whole is not None:
                        whole[..., lo:hi] = part
            image = np.empty((1 + (k or 1), batches, height, width))
            self._splat_rows(out, 0, range(height), per_batch, image)
            tally = Tally(value=image[0], derivative=image[1] if k is None else image[1:])
        return tally if extra is None else Tally(tally.value, tally.derivative + extra)

    @property
    def chunk_pixels(self) -> int:
        """Pixels per memory chunk: at most :data:`CHUNK` // spp (at least one), fewer where that gives each
        thread several chunks (:func:`sphere3d.execution.chunk_size`)."""
        return execution.chunk_size(self.shape[0] * self.shape[1], self.spp, max(1, CHUNK // self.spp))

    def pixel_bytes(self) -> float:
        r"""Memory model of the image: bytes held per pixel and batch until the image is made.

        :data:`~flatland.core.budget.IMAGE_BYTES_PER_PIXEL`, for the per-batch images, whatever the film:
        the splat film's stencils are held for a tile of rows at a time (:meth:`_splat_tiles`), a
        bounded working set apart from the image (:meth:`film_terms`).
        """
        return IMAGE_BYTES_PER_PIXEL

    def _stencil_bytes(self) -> int:
        r"""Bytes of the splat film's buffers per pixel (:meth:`_splat_buffers`): $Q (2h + 1)^2$ float64 per
        batch (Q = 2q quantities with the control variate, else q, q = 1 + the number of tangents; h from
        :func:`~sphere3d.film.reach`), and with the control variate the radiance totals, q float64 per
        pixel (per batch with ``cv_scope="batch"``)."""
        cv = self._cv_samples(self.batches, self.spp // self.batches) > 0
        _, h = reach(self.scene.camera.filter)
        q = 1 + (self.k or 1)
        stencils = (2 * q if cv else q) * self.batches * (2 * h + 1) ** 2 * 8
        return stencils + (q * 8 * (1 if self.cv_scope == "pixel" else self.batches) if cv else 0)

    def _tile(self) -> tuple[int, int]:
        r"""The splat film's tiles (:meth:`_splat_tiles`): memory chunks per tile, and the pixels its
        buffers hold (:meth:`_splat_buffers`).

        A tile is as many chunks as :data:`TILE_BYTES` of stencils hold, at least one per thread
        (:func:`~sphere3d.execution.workers`), at most the image's: T pixels, a multiple of the chunk's.
        The buffers also keep the rows of stencils the next tile's image rows still need: with W
        the image's width, after a tile ending at pixel $p_1$ the rows up to $\lfloor p_1 / W
        \rfloor - h$ are made, and the stencils from h rows above the first row not made are kept,
        fewer than $(2h + 1) W$ pixels'. Hence T + (2h + 1) W pixels (at most the image's).
        """
        height, width = self.shape
        _, h = reach(self.scene.camera.filter)
        per_chunk = self.chunk_pixels * self._stencil_bytes()
        chunks = -(-height * width // self.chunk_pixels)
        tile_chunks = min(chunks, max(1, TILE_BYTES // per_chunk, execution.workers()))
        return tile_chunks, min(height * width, tile_chunks * self.chunk_pixels + (2 * h + 1) * width)

    def film_terms(self) -> tuple[Term, ...]:
        r"""Memory model of the film's working set (:class:`~flatland.core.budget.Term`): with the splat film,
        the buffers of one tile of rows (:meth:`_tile`), $(T + (2h + 1) W) b$ bytes for T pixels per tile,
        W the image's width and b the stencil bytes per pixel (:meth:`_stencil_bytes`): at most
        $\max(\mathrm{TILE\_BYTES}, \text{a chunk's stencils per thread}) + (2h + 1) W b$, whatever the
        image's height; none with the pixel film."""
        if self.film != "splat":
            return ()
        tile_chunks, held = self._tile()
        block = f"the stencils of {held} pixels ({tile_chunks} memory chunks and their neighbours' rows)"
        what = "each sample in every pixel its filter covers"
        return (Term("film", self.film, what, block, at_once=held * self._stencil_bytes()),)

    def _splat_buffers(self, pixels: int, k: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """The chunks' outputs for :meth:`_splat_chunk`, columns for ``pixels`` pixels: stencils
        (quantities, batches, slots, pixels), 2q quantities with the control variate and q without (q = 1 +
        the number of tangents: the estimate and its tangents, then the weights and theirs; ``k`` of
        them, or one), and the pixels' radiance totals (value and tangents)."""
        per_batch = self.spp // self.batches
        cv = self._cv_samples(self.batches, per_batch) > 0
        _, h = reach(self.scene.camera.filter)
        q = 1 + (k or 1)
        stencils = np.empty((2 * q if cv else q, self.batches, (2 * h + 1) ** 2, pixels))
        totals = np.empty((q, 1 if self.cv_scope == "pixel" else self.batches, pixels)) if cv else None
        return stencils, totals

    def _splat_chunk(
        self,
        samples: PixelSamples,
        pix: np.ndarray,
        batches: int,
        per_batch: int,
        out: tuple,
        offset: int = 0,
    ) -> None:
        r"""One chunk's splatted estimates as stencils (:func:`~sphere3d.film.stencil`), written to its
        pixels' columns of ``out`` (:meth:`_splat_buffers`; its column 0 is pixel ``offset``): value and
        tangent, then those of the weights $w_{i,p}$ of samples i in pixels p other than their own, and
        the radiance totals of its pixels.

        Control variate (:mod:`sphere3d.film`), value and tangent: $Σ_i e_{i,p}$ minus
        $Σ_i c_{p,-i} (w_{i,p} - [i ∈ p])$, $c_{p,-i}$ the mean radiance of pixel p's samples
        without i (all of them when i is another pixel's; same expectation for every i,
        independent of i), as a Dual: the tangent is the value's derivative, $c \dot w + \dot c
        (w - [i ∈ p])$. Unbiased: a batch holds equally many samples of every pixel, so
        $E Σ_i w_{i,p} = n$ and $E Σ_i \dot w_{i,p} = 0$ for every θ (pooled over the samplers,
        :mod:`sphere3d.film`); the $[i ∈ p]$ count n. It removes the noise of the weights'
        sum (a constant radiance gives its value exactly, and its derivative: the radiance's
        $\dot L$ splatted) and the filter derivative's $L \dot w$ (:meth:`_control_variate`).
        The other pixels' part is applied in :meth:`_splat_rows`.
        Off where :meth:`_control_variate` is (``cv_scope="off"``, one sample per scope, box).
        For k parameters each tangent is one single parameter's (:func:`~sphere3d.film.splat_stencils`).
        """
        _, h = reach(self.scene.camera.filter)
        cols = slice(pix[0] - offset, pix[-1] + 1 - offset)
        buffers = tuple(part[..., cols] if part is not None else None for part in out)
        slot = samples.slot.reshape(batches, pix.size, per_batch, samples.weight.shape[-1])
        cv = (self._cv_samples(batches, per_batch), self._leave_one_out) if buffers[1] is not None else None
        k = k_of(samples.radiance, samples.weight)
        splat_stencils(samples.radiance, samples.weight, slot, k, h, cv, buffers)

    def _splat_tiles(self, chunk: Any, chunks: range, batches: int, per_batch: int, k: int | None) -> Tally:
        r"""The splat film's image, tile by tile: the stencils of a tile of memory chunks (:meth:`_tile`;
        ``chunk(c, out, offset)`` writes chunk c's, :meth:`_splat_chunk`), then every image row whose
        sources are all done (:meth:`_splat_rows`), before the next tile.

        A target row r sums the stencils of the source rows r - h to r + h (:func:`~sphere3d.film.reach`),
        so after the chunks up to pixel $p_1$ (row-major, W per row) the rows $r < \lfloor p_1 / W
        \rfloor - h$ are complete (all of them after the last chunk). The buffers then drop the source
        rows more than h above the first row not made, moving the rest to their front; what is held
        for the whole image is its per-batch value and tangent. Each pixel is the same sum in the same
        order (:func:`~sphere3d.film.gather`) whatever the tiles, so the image does not depend on
        :data:`TILE_BYTES`, nor on the chunks (a source pixel's stencil is its own samples' sums).
        """
        height, width = self.shape
        _, h = reach(self.scene.camera.filter)
        pixels, chunk_pixels = height * width, self.chunk_pixels
        tile_chunks, held = self._tile()
        out = self._splat_buffers(held, k)
        image = np.empty((1 + (k or 1), batches, height, width))
        lo, done = 0, 0  # the pixel in the buffers' column 0; the first image row not made
        progress.start(len(chunks))  # one pass, advanced tile by tile
        for first in range(chunks.start, chunks.stop, tile_chunks):
            tile = range(first, min(chunks.stop, first + tile_chunks))
            stop = min(pixels, tile.stop * chunk_pixels)  # the tile's chunks write pixels up to here
            execution.map_chunks(functools.partial(chunk, out=out, offset=lo), tile, counted=False)
            progress.advance(len(tile))
            ready = height if stop == pixels else max(done, stop // width - h)
            if ready > done:
                self._splat_rows(out, lo // width, range(done, ready), per_batch, image)
                done = ready
            keep = max(0, done - h) * width  # the first source pixel an image row not made needs
            if keep > lo:
                for part in out:
                    if part is not None:
                        part[..., : stop - keep] = part[..., keep - lo : stop - lo]  # overlap: numpy copies
                lo = keep
        return Tally(value=image[0], derivative=image[1] if k is None else image[1:])

    def _splat_rows(self, out: tuple, first: int, rows: range, per_batch: int, image: np.ndarray) -> None:
        """Image ``rows`` from the stencils (:func:`~sphere3d.film.gather`, in bands of rows on the threads),
        written to ``image`` (value and tangents, batches, height, width): value and tangents, minus the
        other pixels' samples' weights times their target's mean radiance. ``out`` holds the source rows
        from ``first`` on, every row the image rows need."""
        height, width = self.shape
        batches = image.shape[1]
        _, h = reach(self.scene.camera.filter)
        stencils, totals = out
        stencils = stencils[..., : (min(height, rows.stop + h) - first) * width]  # whole rows only
        step = -(-len(rows) // (2 * execution.workers()))

        def bands(i: int) -> None:
            part = range(rows.start + i * step, min(rows.stop, rows.start + (i + 1) * step))
            sums = gather(stencils, height, width, h, part, first).reshape(len(stencils), batches, -1)
            mean = None
            if totals is not None:
                mean = totals[..., (part.start - first) * width : (part.stop - first) * width]
            for i, band in enumerate(splat_band(sums, mean, per_batch, self._cv_samples(batches, per_batch))):
                image[i, :, part.start : part.stop] = band.reshape(batches, len(part), width)

        execution.map_chunks(bands, range(-(-len(rows) // step)), counted=False)


def _remote(shared: tuple[ImageTask | PointTask, Any, Transforms, int], item: tuple[int, int] | None) -> Any:
    """One task of :meth:`ImageTask._on_cluster` or :meth:`PointTask._on_cluster` on a worker: with
    ``item`` = (first, stop) the ``_chunk_range`` of those chunks (the client's chunk size: pixels of an
    image, samples at a point), with None the per-image term ``pixel_extra``; both from a scene state
    built here."""
    task, theta, transforms, chunk_size = shared
    state = build_state(task.scene, task.param, theta, task.tracer)
    if item is None:
        return transforms.pixel_extra(task, state)
    return task._chunk_range(state, transforms, *item, chunk_size)


@dataclass(frozen=True)
class PointTask(_Parameters):
    r"""The irradiance $E = ∫ L_i \cos θ\, dω$ at a fixed point with a fixed unit normal: ``n`` samples; with
    ``max_depth`` d > 1, $L_i$ carries paths of up to d - 1 further diffuse vertices (:mod:`sphere3d.paths`).
    """

    scene: Scene
    param: str | tuple[str, ...] | None
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    n: int
    seed: int
    batches: int
    tracer: str = "embree"
    max_depth: int = 1

    @property
    def shape(self) -> tuple[()]:
        return ()

    def evaluate(self, theta: Any, transforms: Transforms | None = None) -> Tally:
        """Estimate E at the point with the parameter offset by ``theta`` under ``transforms``.

        A batch's samples are memory chunks of :data:`CHUNK` (batch-major), every sample's numbers keyed
        on its index; a batch's mean is its chunks' sums added in chunk order, wherever they were
        computed. Inside :func:`sphere3d.execution.cluster` the chunks run on a Dask cluster
        (:meth:`_on_cluster`).
        """
        transforms = transforms or Identity()
        per_batch = self.n // self.batches
        k = -(-per_batch // CHUNK)  # memory chunks per batch
        if execution.client() is not None:
            sums = self._on_cluster(theta, transforms, self.batches * k)
        else:
            state = build_state(self.scene, self.param, theta, self.tracer)
            chunk = functools.partial(self._chunk, state, transforms, CHUNK)
            sums = execution.map_chunks(chunk, range(self.batches * k))
        return _tally([sum(sums[b * k : (b + 1) * k]) / per_batch for b in range(self.batches)], ())

    def _chunk(self, state: Any, transforms: Transforms, size: int, i: int) -> Any:
        """The sum of the estimates of memory chunk ``i = b * k + c``: chunk c of batch b, k chunks of
        ``size`` samples per batch."""
        per_batch = self.n // self.batches
        b, c = divmod(i, -(-per_batch // size))
        count = min(size, per_batch - c * size)
        x, nrm = (np.broadcast_to(np.array(v), (count, 3)).copy() for v in (self.point, self.normal))
        if state.dual:
            x, nrm = Dual(x, None, state.k), Dual(nrm, None, state.k)
        # sample j = b * per_batch + c * size + s of the point: its numbers are keyed on j
        draws = Draws.of(self.seed, b * per_batch + c * size + np.arange(count))
        u = draws.uniforms("samples", 5)
        return np.sum(irradiance_paths(Shading.at(state, x, nrm, draws), u, transforms, self.max_depth))

    def _chunk_range(self, state: Any, transforms: Transforms, first: int, stop: int, size: int) -> list[Any]:
        """The sums of memory chunks ``first`` to ``stop`` (exclusive) of ``size`` samples (:meth:`_chunk`),
        on this machine's threads."""
        chunk = functools.partial(self._chunk, state, transforms, size)
        return execution.map_chunks(chunk, range(first, stop), counted=False)

    def _on_cluster(self, theta: Any, transforms: Transforms, chunks: int) -> list[Any]:
        """The sums of :meth:`evaluate`'s ``chunks`` memory chunks, as tiles on the Dask cluster of
        :func:`~sphere3d.execution.client`.

        The chunks are this process's (:data:`CHUNK` samples); a tile is a run of whole chunks
        (:func:`~sphere3d.execution.tile_ranges`), computed on a worker by :meth:`_chunk_range` from the
        pickled task, θ and transforms, the worker building its own scene state and tracer. Each chunk's
        sum is thus that of a local run, and :meth:`evaluate` adds them in the local order: the estimate
        is bit for bit the local one.
        """
        tiles = execution.map_tiles(_remote, (self, theta, transforms, CHUNK), execution.tile_ranges(chunks))
        return [s for tile in tiles for s in tile]
