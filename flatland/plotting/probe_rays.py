"""The probe-ray figure of tutorial 8: a flatland scene, the probes around one sample, the point chosen.

Loubet et al. 2019, Sec. 4.3 (theory/probes): a few probe rays are traced from the
integral's origin inside the kernel's support, and :func:`flatland.reparam.probes.select_points`
picks from their hits the point whose motion the transform follows.
:func:`plot_probes` draws one such choice from data computed elsewhere (matplotlib only,
no numerics; the figure is made without pyplot):

- the scene's segments, each in its own colour (thick when it moves with θ);
- the probes from the origin, in angular order and numbered: a probe that hits is
  drawn in the colour of the segment it hits, a miss dashed in grey;
- the pair of the rule (probe 0 and its partner) thick;
- the bracket, two adjacent probes that see different things, as a shaded wedge: the
  discontinuity lies between them;
- the tangent lines of the occlusion test and of the corner, dotted;
- the chosen point, a star in the reparameterization's colour.

The colours come from :mod:`flatland.plotting.style`. Every artist carries a ``gid``
(``"segment"``, ``"probe"``, ``"bracket"``, ``"tangent"``, ``"origin"``, ``"point"``) so
a test can find it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon

from flatland.core.validate import ValidationError
from flatland.plotting.style import METHOD_COLOURS, OTHER_COLOURS, new_axes

__all__ = ["CHOSEN_COLOUR", "MISS_COLOUR", "SEGMENT_COLOURS", "TANGENT_STYLE", "plot_probes"]

SEGMENT_COLOURS = OTHER_COLOURS[:-1]
"""Colour of segment k: ``SEGMENT_COLOURS[k % 5]`` (no method's colour, and not the misses' grey)."""
MISS_COLOUR = OTHER_COLOURS[-1]
"""Colour of a probe that hits nothing (grey)."""
CHOSEN_COLOUR = METHOD_COLOURS["reparam"]
"""Colour of the chosen point: the point the reparameterization follows."""
TANGENT_STYLE = {"color": METHOD_COLOURS["reference"], "linestyle": ":", "linewidth": 1.0}
"""How a tangent line of the occlusion test is drawn."""
THIN, THICK = 1.2, 2.6
"""Line widths of a probe, and of the pair's probes (and of a moving segment, ``THICK + 1``)."""


def _points(name: str, value: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (None: any length), else a ValidationError."""
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True)):
        raise ValidationError(name, f"must have shape {shape} (None: any), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValidationError(name, "must be finite")
    return a


def _indices(name: str, value: Any, size: int) -> tuple[int, int] | None:
    """A pair of probe indices in [0, size), or None."""
    if value is None:
        return None
    pair = tuple(int(i) for i in value)
    if len(pair) != 2 or not all(0 <= i < size for i in pair):
        raise ValidationError(name, f"must be two probe indices in [0, {size}), got {value!r}")
    return pair  # type: ignore[return-value]


def plot_probes(
    segments: Any,
    origin: Any,
    ends: Any,
    hits: Any,
    *,
    pair: Sequence[int] | None = None,
    bracket: Sequence[int] | None = None,
    point: Any = None,
    tangents: Sequence[tuple[Any, Any]] = (),
    moving: Sequence[int] = (),
    ax: Axes | None = None,
    title: str | None = None,
) -> Figure:
    """Draw the probes around one sample and the point the heuristic chose (Loubet et al. 2019, Sec. 4.3).

    Parameters
    ----------
    segments : array_like, shape (m, 2, 2)
        The scene's segments, end points a and b (segment k is primitive k).
    origin : array_like, shape (2,)
        Where the probes start (the camera, or a shading point).
    ends : array_like, shape (P, 2)
        Where each probe is drawn to, in angular order: its hit point, or a point
        along its direction for a miss.
    hits : array_like of int, shape (P,)
        The segment each probe hits, -1 for a miss.
    pair : (int, int), optional
        Probe 0 and its partner (the last probe that hits another shape), drawn thick.
    bracket : (int, int), optional
        Two adjacent probes that see different things, shaded as a wedge.
    point : array_like, shape (2,), optional
        The chosen point (None: the identity, nothing chosen).
    tangents : sequence of (point, normal)
        Tangent lines to draw, each through ``point`` perpendicular to ``normal``.
    moving : sequence of int
        Segments that move with θ, drawn thicker.
    ax, title
        Draw into ``ax`` instead of a new figure; the panel's title.

    Returns
    -------
    Figure
    """
    segs = _points("segments", segments, (None, 2, 2))
    o = _points("origin", origin, (2,))
    ends = _points("ends", ends, (None, 2))
    n_probes = ends.shape[0]
    hits = np.asarray(hits)
    if hits.shape != (n_probes,) or not np.issubdtype(hits.dtype, np.integer):
        raise ValidationError("hits", f"must be {n_probes} integers (one per probe), got {hits!r}")
    if np.any((hits < -1) | (hits >= segs.shape[0])):
        raise ValidationError("hits", f"must be -1 or a segment index below {segs.shape[0]}, got {hits}")
    pair = _indices("pair", pair, n_probes)
    bracket = _indices("bracket", bracket, n_probes)
    ax = new_axes(ax, title, figsize=(4.4, 4.0))
    moving = {int(k) for k in moving}
    for k, (a, b) in enumerate(segs):
        width = THICK + 1.0 if k in moving else 2.0
        ax.plot([a[0], b[0]], [a[1], b[1]], color=SEGMENT_COLOURS[k % len(SEGMENT_COLOURS)],
                linewidth=width, solid_capstyle="butt", gid="segment")  # fmt: skip
    if bracket is not None:
        wedge = Polygon(np.stack([o, ends[bracket[0]], ends[bracket[1]]]), closed=True, gid="bracket",
                        facecolor=CHOSEN_COLOUR, alpha=0.15, edgecolor="none")  # fmt: skip
        ax.add_patch(wedge)
    for i, (end, hit) in enumerate(zip(ends, hits, strict=True)):
        colour = SEGMENT_COLOURS[hit % len(SEGMENT_COLOURS)] if hit >= 0 else MISS_COLOUR
        width = THICK if pair is not None and i in pair else THIN
        ax.plot([o[0], end[0]], [o[1], end[1]], color=colour, linewidth=width,
                linestyle="-" if hit >= 0 else "--", gid="probe")  # fmt: skip
        ax.annotate(str(i), end, textcoords="offset points", xytext=(3, 3), fontsize=8, color=colour)
    for p, n in tangents:
        p, n = _points("tangents", p, (2,)), _points("tangents", n, (2,))
        ax.axline(p, p + np.array([-n[1], n[0]]), gid="tangent", **TANGENT_STYLE)
    ax.plot([o[0]], [o[1]], marker="o", color=METHOD_COLOURS["reference"], linestyle="none", gid="origin")
    if point is not None:
        q = _points("point", point, (2,))
        ax.plot([q[0]], [q[1]], marker="*", markersize=15, color=CHOSEN_COLOUR, linestyle="none",
                markeredgecolor="white", zorder=5, gid="point")  # fmt: skip
    everything = np.concatenate([segs.reshape(-1, 2), ends, o[None]])
    low, high = everything.min(axis=0), everything.max(axis=0)
    margin = 0.08 * np.max(high - low) + 1e-9
    ax.set_xlim(low[0] - margin, high[0] + margin)
    ax.set_ylim(low[1] - margin, high[1] + margin)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    legend = [
        Line2D([], [], color=SEGMENT_COLOURS[0], linewidth=THIN, label="probe (colour of what it hits)"),
        Line2D([], [], color=MISS_COLOUR, linewidth=THIN, linestyle="--", label="probe that misses"),
    ]
    if pair is not None:
        legend.append(Line2D([], [], color="0.3", linewidth=THICK, label="pair: probe 0 and its partner"))
    if bracket is not None:
        legend.append(Patch(facecolor=CHOSEN_COLOUR, alpha=0.15, label="bracket (adjacent, differ)"))
    if tangents:
        legend.append(Line2D([], [], label="tangent line", **TANGENT_STYLE))
    if point is not None:
        legend.append(Line2D([], [], color=CHOSEN_COLOUR, marker="*", markersize=10, linestyle="none",
                             label="chosen point"))  # fmt: skip
    ax.legend(handles=legend, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=7)
    return ax.figure
