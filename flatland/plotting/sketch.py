r"""Scene sketches: the geometry behind a flatland film, drawn beside it.

A 1D film shows stripes; the sketch shows what makes them. :func:`draw_scene` draws,
in scene coordinates with equal aspect:

* every shape: segments and polylines as lines, polygons and circles outlined and
  lightly filled, each with its name;
* emitters in their own colour, with short ticks on the emitting side of a one-sided
  segment (its right, looking from its first point to its second);
* the pinhole camera, its frustum (the field of view, film coordinates
  t in $[-\tan(\mathrm{fov}/2), \tan(\mathrm{fov}/2)]$) and its film, with the end of pixel 0 marked;
* with a parameter: the part θ moves (or whose emission, albedo or roughness θ changes) under a
  translucent halo, arrows of its points' velocity $dp/dθ$ scaled by a small step dθ,
  and the part at $θ + dθ$ dashed, to first order $p + dθ · dp/dθ$ (the arrows end on it).

The velocities are the tangents of the :class:`~flatland.state.SceneState` built
with a Dual θ, the same forward-mode derivatives the gradient methods differentiate
(Loubet et al. 2019, Sec. 3: the discontinuities move with the geometry). Colours come
from :data:`~flatland.plotting.style.SKETCH_COLOURS`, none of which a method uses.
Nothing here imports pyplot.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon
from matplotlib.transforms import ScaledTranslation

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.validate import ValidationError, check_finite
from flatland.plotting.style import SKETCH_COLOURS, new_axes

__all__ = ["SKETCH_COLOURS", "draw_scene", "plot_scene", "scene_state"]

SCENE_SHARE, PART_SHARE = 0.12, 0.3
"""Default step dθ: no point moves by more than these shares of the scene's extent and of its own
shape's size (a small step keeps the first-order copy of a rotated or scaled shape close to the true one)."""
_TINY = 1e-12  # speeds below this (relative to the largest) count as "does not move"
_MOVED = {"lw": 1.3, "ls": "--"}  # the scene at θ + dθ: its drawn outlines and their legend entry


def scene_state(scene: Any, param: str | None = None, theta: float = 0.0) -> tuple[Any, Any]:
    """``(scene or None, state)``: the :class:`~flatland.state.SceneState` to draw, with Dual θ.

    ``scene`` is anything :func:`~flatland.scene.load_scene` accepts, or a SceneState
    (then ``param`` must be None: the state's Duals already say what moves, and its
    shapes have no names).
    """
    from flatland.scene import load_scene  # the renderer's modules load only when a sketch is drawn
    from flatland.state import SceneState, build_state

    theta = check_finite("theta", theta)
    if isinstance(scene, SceneState):
        if param is not None:
            raise ValidationError("param", f"must be None with a SceneState (it carries θ), got {param!r}")
        return None, scene
    scene = load_scene(scene)
    return scene, build_state(scene, param, variable(theta) if param is not None else theta)


def _pairs(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """(value, tangent) of a state array as float arrays (zero tangent when it is plain)."""
    return np.asarray(detach(x), dtype=np.float64), np.asarray(tangent(x), dtype=np.float64)


def _parts(scene: Any, state: Any) -> list[dict[str, Any]]:
    """One record per shape: its points, their velocities, whether it emits, moves or changes."""
    a, a_dot = _pairs(state.seg_a)
    b, b_dot = _pairs(state.seg_b)
    c, c_dot = _pairs(state.circ_c)
    r, r_dot = _pairs(state.circ_r)
    emission, emission_dot = _pairs(state.emission)
    _, albedo_dot = _pairs(state.albedo)
    _, roughness_dot = _pairs(state.roughness)
    n_seg = a.shape[0]
    parts = []
    for k in dict.fromkeys(state.prim_shape.tolist()):  # shapes in scene order
        prims = np.flatnonzero(state.prim_shape == k)
        segs, circs = prims[prims < n_seg], prims[prims >= n_seg] - n_seg
        part: dict[str, Any] = {
            "name": scene.shapes[k].name if scene is not None else f"shape {k}",
            "emitter": bool(np.any(emission[prims] > 0.0)),
            "one_sided": bool(np.any(state.one_sided[prims])),
            "changes": bool(
                np.any(emission_dot[prims] != 0.0)
                or np.any(albedo_dot[prims] != 0.0)
                or np.any(roughness_dot[prims] != 0.0)
            ),
        }
        if circs.size:  # a circle shape is one primitive
            i = int(circs[0])
            angles = np.array([0.0, 0.5, 1.0, 1.5]) * math.pi  # four boundary points: p = c + r n
            normals = np.stack([np.cos(angles), np.sin(angles)], axis=1)
            grows = r_dot[i] != 0.0  # a growing circle: the boundary moves at c' + r' n
            part.update(
                circle=(c[i], r[i]),
                moved_circle=(c_dot[i], r_dot[i]),
                points=c[i] + r[i] * normals if grows else c[i][None, :],
                velocity=c_dot[i] + r_dot[i] * normals if grows else c_dot[i][None, :],
            )
        else:
            ends, ends_dot = a[segs], a_dot[segs]
            closed = segs.size > 2 and np.allclose(b[segs[-1]], a[segs[0]])
            if not closed:  # an open chain also shows its last point
                ends, ends_dot = np.vstack([ends, b[segs[-1:]]]), np.vstack([ends_dot, b_dot[segs[-1:]]])
            part.update(segments=(a[segs], b[segs]), closed=closed, points=ends, velocity=ends_dot)
        part["moves"] = bool(np.any(part["velocity"] != 0.0))
        parts.append(part)
    return parts


def _camera(state: Any, reach: float, film: float) -> dict[str, Any]:
    r"""The camera's position, frustum corners and film ends, with their velocities (Dual arithmetic).

    The frustum's edge rays point along $(f ± h r) / \sqrt{1 + h^2}$, $h = \tan(\mathrm{fov}/2)$, $f ⟂ r$
    unit; the film is drawn at the distance ``film`` in front of the pinhole.
    """
    h = state.camera.half_width
    o, f, r = (
        x if isinstance(x, Dual) else Dual(np.asarray(x, dtype=np.float64))
        for x in (state.cam_o, state.cam_f, state.cam_r)
    )
    edges = [(f + s * h * r) / math.sqrt(1.0 + h * h) for s in (-1.0, 1.0)]  # left (pixel 0), right
    corners = [o + reach * e for e in edges]
    ends = [o + film * (f + s * h * r) for s in (-1.0, 1.0)]
    points = [o, *corners]
    return {
        "origin": detach(o),
        "corners": [detach(p) for p in corners],
        "film": [detach(p) for p in ends],
        "points": np.array([detach(p) for p in points]),
        "velocity": np.array([tangent(p) for p in points]),
        "moves": any(np.any(tangent(x) != 0.0) for x in (o, f)),
    }


def _extent(parts: list[dict[str, Any]], origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower-left and upper-right corners of the shapes and the camera."""
    pts = [origin[None, :]]
    for p in parts:
        if "circle" in p:
            c, r = p["circle"]
            pts.append(np.array([c - r, c + r]))
        else:
            pts += list(p["segments"])
    allp = np.vstack(pts)
    return allp.min(axis=0), allp.max(axis=0)


def _outline(ax: Axes, p: dict[str, Any], gid: str, step: float = 0.0, **style: Any) -> None:
    """The part's geometry moved by ``step · dp/dθ`` (first order): a circle, a polygon or lines."""
    if "circle" in p:
        (c, r), (c_dot, r_dot) = p["circle"], p["moved_circle"]
        ax.add_patch(Circle(c + step * c_dot, r + step * r_dot, gid=gid, **style))
    elif p["closed"]:
        ax.add_patch(Polygon(p["points"] + step * p["velocity"], closed=True, gid=gid, **style))
    else:
        pts = p["points"] + step * p["velocity"]  # an open chain: point k to point k + 1
        ax.add_collection(LineCollection(np.stack([pts[:-1], pts[1:]], axis=1), gid=gid, **style))


def _draw_part(ax: Axes, p: dict[str, Any], step: float, size: float) -> None:
    """One shape: outline (emitter colour if it emits), halo if it moves or changes, the moved copy."""
    colour = SKETCH_COLOURS["emitter"] if p["emitter"] else SKETCH_COLOURS["shape"]
    kind, name, green = "emitter" if p["emitter"] else "shape", p["name"], SKETCH_COLOURS["moving"]
    solid = "circle" in p or p["closed"]
    fill = {"facecolor": SKETCH_COLOURS["fill"]} if solid else {}
    line = "edgecolor" if solid else "color"
    _outline(ax, p, f"{kind}:{name}", lw=3.0 if p["emitter"] else 2.0, zorder=3, **{line: colour}, **fill)
    if p["moves"] or p["changes"]:
        halo = {"fill": False} if solid else {}
        _outline(ax, p, f"moving:{name}", lw=9, alpha=0.35, zorder=2, **{line: green}, **halo)
    if p["moves"]:
        halo = {"fill": False} if solid else {}
        _outline(ax, p, f"moved:{name}", step, zorder=4, **_MOVED, **{line: green}, **halo)
    if p["emitter"] and p["one_sided"] and "segments" in p:  # ticks on the emitting side: right of a -> b
        a, b = p["segments"]
        d = b - a
        normal = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.linalg.norm(d, axis=1)[:, None]
        feet = np.concatenate([a + s * d for s in (0.25, 0.5, 0.75)])
        ticks = np.stack([feet, feet + 0.035 * size * np.tile(normal, (3, 1))], axis=1)
        ax.add_collection(LineCollection(ticks, colors=colour, linewidths=1.2, gid=f"emits:{name}", zorder=3))
    if "circle" in p:
        top = p["circle"][0] + np.array([0.0, p["circle"][1]])  # name above the shape
    else:
        top = np.array([np.mean(p["points"][:, 0]), np.max(p["points"][:, 1])])
    ax.annotate(name, top, xytext=(0, 6), textcoords="offset points", ha="center", fontsize=7, color="0.2")


def _default_step(parts: list[dict[str, Any]], cam: dict[str, Any], size: float) -> float:
    """dθ: no point moves by more than PART_SHARE of its shape's size or SCENE_SHARE of the scene."""
    limits = []
    for p in [*parts, cam]:
        speed = float(np.linalg.norm(p["velocity"], axis=1).max())
        if "circle" in p:
            own = 2.0 * p["circle"][1]
        elif p is cam:
            own = size
        else:
            own = float(np.linalg.norm(np.ptp(p["points"], axis=0)))
        if speed > 0.0:
            limits.append(min(PART_SHARE * max(own, 0.05 * size), SCENE_SHARE * size) / speed)
    return min(limits, default=0.0)


def _arrows(ax: Axes, points: np.ndarray, velocity: np.ndarray, step: float, gid: str, floor: float) -> None:
    """Arrows from ``points`` along ``step · velocity`` (in data units), for points that move."""
    keep = np.linalg.norm(velocity, axis=1) > floor
    if np.any(keep):
        p, v = points[keep], step * velocity[keep]
        ax.quiver(
            p[:, 0],
            p[:, 1],
            v[:, 0],
            v[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0,
            color=SKETCH_COLOURS["moving"],
            width=0.008,
            zorder=5,
            gid=gid,
        )


def draw_scene(
    ax: Axes,
    scene: Any,
    param: str | None = None,
    *,
    theta: float = 0.0,
    step: float | None = None,
    title: str | None = None,
    legend: bool = True,
) -> Axes:
    """Draw a flatland scene into ``ax``: shapes, emitters, camera frustum and, given ``param``, its motion.

    Parameters
    ----------
    ax : Axes
        Where to draw; it gets equal aspect, axis labels x and y, and a title.
    scene : Scene, str, dict, path or SceneState
        A scene (anything :func:`~flatland.scene.load_scene` accepts) or a
        :class:`~flatland.state.SceneState` built with a Dual θ (then ``param`` is None).
    param : str, optional
        The parameter θ binds; its part is marked and its motion drawn.
    theta : float
        The parameter's offset at which the scene is drawn (0: the scene as loaded).
    step : float, optional
        The step dθ of the arrows and of the dashed copy (shown in the legend); None:
        no point moves by more than :data:`PART_SHARE` of its shape's size or
        :data:`SCENE_SHARE` of the scene's extent.
    title : str, optional
        Default: the scene's name and the parameter.
    legend : bool
        Add a legend of the elements drawn.

    Returns
    -------
    Axes
    """
    scene, state = scene_state(scene, param, theta)
    parts = _parts(scene, state)
    origin = np.asarray(detach(state.cam_o), dtype=np.float64)
    low, high = _extent(parts, origin)
    size = float(max(np.max(high - low), 1e-9))
    reach = 1.5 * float(np.max(np.linalg.norm(np.vstack([low, high]) - origin, axis=1)))  # past every shape
    cam = _camera(state, reach, film=0.08 * size)
    fastest = max(float(np.linalg.norm(p["velocity"], axis=1).max()) for p in [*parts, cam])
    if step is None:
        step = _default_step(parts, cam, size)
    elif check_finite("step", step) == 0.0:
        raise ValidationError("step", f"must be non-zero, got {step!r}")
    floor = _TINY * max(fastest, 1.0)

    for p in parts:
        _draw_part(ax, p, step, size)
        if p["moves"]:
            _arrows(ax, p["points"], p["velocity"], step, f"motion:{p['name']}", floor)
    camera_colour = SKETCH_COLOURS["camera"]
    wedge = np.array([cam["origin"], *cam["corners"]])
    ax.add_patch(
        Polygon(
            wedge, closed=True, facecolor=camera_colour, alpha=0.12, edgecolor="none", gid="frustum", zorder=1
        )
    )
    ax.add_collection(
        LineCollection(
            [wedge[[0, 1]], wedge[[0, 2]]],
            colors=camera_colour,
            linewidths=0.8,
            linestyles=":",
            gid="frustum_edges",
            zorder=1,
        )
    )
    ax.add_line(Line2D(*np.array(cam["film"]).T, color=camera_colour, lw=2.5, gid="film", zorder=5))
    ax.add_line(
        Line2D(
            [origin[0]],
            [origin[1]],
            marker="o",
            ms=6,
            color=camera_colour,
            mec=SKETCH_COLOURS["moving"] if cam["moves"] else camera_colour,
            mew=2,
            gid="camera",
            zorder=6,
        )
    )
    ax.annotate(
        "pixel 0",
        cam["film"][0],
        xytext=(0, -8),
        textcoords="offset points",
        ha="center",
        fontsize=6,
        color=camera_colour,
        zorder=6,
    )
    if cam["moves"]:
        moved = cam["points"] + step * cam["velocity"]
        ax.add_line(
            Line2D(
                *moved[[1, 0, 2]].T,
                color=SKETCH_COLOURS["moving"],
                **_MOVED,
                gid="moved:camera",
                zorder=4,
            )
        )
        _arrows(ax, cam["points"], cam["velocity"], step, "motion:camera", floor)

    pad = 0.08 * size
    ax.set_xlim(low[0] - pad, high[0] + pad)
    ax.set_ylim(low[1] - pad, high[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    name = scene.name if scene is not None else "scene"
    ax.set_title(title if title is not None else name + (f": {param}" if param else ""), fontsize=10)
    if legend:
        _legend(ax, parts, cam, param, step)
    return ax


def _legend(ax: Axes, parts: list[dict[str, Any]], cam: dict[str, Any], param: Any, step: float) -> None:
    """Proxy legend entries for what is drawn (a Quiver has no legend handle of its own)."""
    colours = SKETCH_COLOURS
    handles = [Line2D([], [], color=colours["shape"], lw=2, label="shape")]
    if any(p["emitter"] for p in parts):
        handles.append(Line2D([], [], color=colours["emitter"], lw=3, label="emitter"))
    handles.append(Line2D([], [], color=colours["camera"], marker="o", lw=2.5, label="camera, film, view"))
    moving = any(p["moves"] for p in parts) or cam["moves"]
    if moving or any(p["changes"] for p in parts):
        what = "moves with θ" if moving else "changes with θ"
        handles.append(Line2D([], [], color=colours["moving"], lw=7, alpha=0.35, label=param or what))
    if moving:
        handles.append(
            Line2D(
                [],
                [],
                color=colours["moving"],
                **_MOVED,
                marker=">",
                ms=5,
                label=f"at θ + dθ, dθ = {step:.2g}",
            )
        )
    below = ax.transAxes + ScaledTranslation(0.0, -32 / 72, ax.figure.dpi_scale_trans)  # under the x label
    ax.legend(handles=handles, fontsize=6, ncols=2, loc="upper center", bbox_to_anchor=(0.5, 0.0),
              bbox_transform=below, frameon=False)  # fmt: skip


def plot_scene(
    scene: Any,
    param: str | None = None,
    *,
    theta: float = 0.0,
    step: float | None = None,
    ax: Axes | None = None,
    title: str | None = None,
    legend: bool = True,
) -> Figure:
    """The scene sketch of :func:`draw_scene` as a figure (made without pyplot), or drawn into ``ax``.

    Returns
    -------
    Figure
    """
    ax = new_axes(ax, None, figsize=(4.4, 4.0))
    draw_scene(ax, scene, param, theta=theta, step=step, title=title, legend=legend)
    return ax.figure
