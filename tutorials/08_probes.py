# ---
# jupyter:
#   jupytext:
#     cell_metadata_filter: -all
#     formats: ipynb,py:percent
#     notebook_metadata_filter: kernelspec,jupytext,-jupytext.text_representation.jupytext_version
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 8. Choosing the transform by ray tracing: probe rays
#
# **What you will learn.**
#
# - how a renderer finds the point to follow: probe rays and the six-step rule of the paper's Sec.
#   4.3, case by case
# - what the chosen point does to a pixel's derivative (slider: the number of probes)
#
# In tutorial 6 we told the translation which point to follow: the bar's end, whose film
# coordinate $t_a(\theta)$ we knew. Tutorial 7 confined each translation to a narrow kernel around
# its sample. A renderer knows neither where the silhouettes in a pixel are nor how they move.
# Loubet et al. (2019, Sec. 4.3) find out by tracing a few *probe rays* inside the kernel's
# support and choosing, with a short heuristic, one point $p$ whose motion the transform follows
# (`docs/theory/probes.md`; in flatland `flatland.reparam.probes.select_points`):
#
# 1. pair probe 0 with the last probe that hits a *different* shape (a miss is "no shape");
# 2. if only one of the pair hits, use its hit point;
# 3. if both hit, test with the tangent line $(p_0, n_0)$ whether it separates $p_1$ from the ray
#    origin $o$, $\text{occludes} = \bigl(n_0\cdot(p_1 - p_0)\bigr)\bigl(n_0\cdot(o - p_0)\bigr) < 0$,
#    and likewise for $(p_1, n_1)$; if exactly one occludes the other, use the point on the occluder;
# 4. if the normals are nearly parallel, $|n_0\cdot n_1| > 0.99$, use $p_0$;
# 5. otherwise intersect the two tangent lines: the corner where the two surfaces meet;
# 6. if no probe hits, or all hit one primitive, nothing is followed: the transform is the identity.
#
# These are the six steps of `docs/theory/probes.md`, numbered the same way there, in the figures
# and in the checks below. The library reports which point it chose in `choice.code` (-1 nothing,
# 0 probe 0's shape, 1 the partner's shape, 2 the corner); `CHOSEN` in the first cell names them.
#
# Of the shape chosen, flatland uses the hit *next to the switch* (the probe on that shape whose
# neighbour sees something else) and can move it toward the discontinuity by bisection. The
# point is *attached*: it keeps its barycentric coordinate and moves with its segment, so its
# derivative is the motion the translation follows.
#
# Each step gets a hand-made scene below, the flatland counterparts of the cases of the
# library's test `tests/flatland/test_methods.py::test04`, made geometrically consistent so that
# the probes can really be traced. For each we draw the scene, the probes, the pair, the bracket
# and the chosen point, and check the chosen point against its value derived by hand. The last
# section shows what the choice is for: the derivative of one pixel, computed with the chosen
# points, against its closed form.
#
# Every scene is seen from a camera at the origin looking along $+y$, so the film coordinate of a
# direction $(x, y)$ is $t = x / y$, and a probe at film coordinate $t$ hits the horizontal line
# $y = Y$ at $(tY, Y)$. Around a sample at $t = 0$ the four probes sit at
# $t_k = \sigma \cdot 3 \cdot (-1, -\tfrac13, \tfrac13, 1) = (-0.3, -0.1, 0.1, 0.3)$ with
# $\sigma = 0.1$: evenly over $\pm 3$ kernel standard deviations, as in the library's default
# (`spread=3`, `probes=4`). The first cell imports the library and fixes the seed and these
# numbers.

# %%
# %matplotlib inline
from typing import NamedTuple

import numpy as np
from scipy import stats

import flatland as fl
from flatland.core.dual import detach, tangent, variable
from flatland.core.rng import stream
from flatland.core.stats import ROUNDING, normal_quantile, sidak
from flatland.core.translation import translation_offset, unit_weight
from flatland.plotting.probe_rays import plot_probes
from flatland.plotting.tutorials import plot_grid
from flatland.reparam.default import default_kappa_film
from flatland.reparam.probes import PARALLEL, film_shape_end, select_points
from flatland.sampling import filter_value, sample_filter
from flatland.scene import load_scene
from flatland.state import build_state
from flatland.tracing import attached_points, cast, film_coordinate, film_direction
from flatland.widgets import explore, probes_view

SEED = 20191117
CAMERA = {"position": [0.0, 0.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 4}
ORIGIN = np.array(CAMERA["position"])
SIGMA, SPREAD, PROBES = 0.1, 3.0, 4
OFFSETS = SIGMA * SPREAD * np.linspace(-1.0, 1.0, PROBES)  # (-0.3, -0.1, 0.1, 0.3)
TOL = ROUNDING * 4.0  # rounding: 64 ulps of the scenes' size (coordinates below 4)
CHOSEN = {-1: "nothing (step 6)", 0: "probe 0's shape", 1: "the partner's shape", 2: "the corner (step 5)"}


def segment(name, a, b, **material):
    return {"name": name, "type": "segment", "points": [a, b], **material}


WALL = segment("wall", [-1.0, 2.0], [1.0, 2.0])  # a background at y = 2

# %% [markdown]
# ## 1. Probe rays around a sample
#
# The first scene is the commonest case: a near segment, the *occluder*, from $(-1, 1)$ to
# $(0, 1)$, in front of the wall at $y = 2$; the occluder moves along $x$ with θ
# (`near.translate.x`). Its right end, at film coordinate $t = 0$, is the discontinuity.
#
# The function `probe` below does what the library's reparameterization does for one film sample
# (`flatland.reparam.default.ReparamTransforms.camera`): it casts the probes *detached* (plain
# floats, like every ray), in film order, and hands their hits — the primitive and the
# barycentric coordinate along it — to `select_points`, together with the θ-dependent scene, a
# direction inside the kernel (its centre, to reject corners behind the camera) and, for
# bisection, the probes' film coordinates and the tracer. It also keeps, for the figures, what
# each probe sees (its shape, -1 for a miss), the pair of step 1, the first *bracket* (two
# adjacent probes that see different shapes: the discontinuity lies between them) and the
# tangent lines of the pair.


# %%
class Probed(NamedTuple):
    geom: object  # the scene with θ bound (Duals)
    prim: np.ndarray  # hit primitive per probe, -1 for a miss
    coord: np.ndarray  # barycentric coordinate of each hit along its segment
    ends: np.ndarray  # hit points (a point along the ray for a miss), for the figure
    shape: np.ndarray  # the shape each probe sees, -1 for nothing
    pair: tuple | None  # probe 0 and its partner
    bracket: tuple | None  # the first two adjacent probes that see different shapes
    tangents: list  # (point, normal) of the pair's hits where both hit
    code: int  # the point chosen (-1 none, 0 probe 0's shape, 1 the partner's, 2 the corner): CHOSEN
    attached: object  # the chosen point, attached: a Dual, shape (1, 2)
    point: np.ndarray  # its value
    velocity: np.ndarray  # its derivative dp/dθ: the motion the transform follows


def probe(shapes, param, refine=0):
    """Trace the probes around the film sample t = 0 and let the heuristic choose (Sec. 4.3)."""
    geom = build_state(
        load_scene({"name": "probes", "camera": CAMERA, "shapes": shapes}), param, variable(0.0)
    )
    geom0 = geom.detached()

    def trace(rows, t):  # film coordinates -> (primitive, coordinate) of the first hit
        hits = cast(geom0, ORIGIN, film_direction(geom0, t))
        return hits.prim, hits.coord

    prim, coord = trace(None, OFFSETS)
    choice = select_points(
        geom,
        ORIGIN[None],
        prim[None],
        coord[None],
        film_direction(geom0, np.zeros(1)),
        OFFSETS[None],
        trace,
        refine,
    )
    hit = prim >= 0
    hit_points, normals = attached_points(geom0, np.maximum(prim, 0), coord)
    ends = np.where(hit[:, None], hit_points, ORIGIN + 3.5 * film_direction(geom0, OFFSETS))
    shape = np.where(hit, geom.prim_shape[np.maximum(prim, 0)], -1)
    differs = np.flatnonzero(shape != shape[0])
    pair = (0, int(differs[-1])) if differs.size else None  # step 1: the last probe that sees another shape
    switch = np.flatnonzero(shape[1:] != shape[:-1])
    bracket = (int(switch[0]), int(switch[0]) + 1) if switch.size else None
    both = pair is not None and hit[list(pair)].all()
    tangents = [(hit_points[i], normals[i]) for i in pair] if both else []
    return Probed(geom, prim, coord, ends, shape, pair, bracket, tangents, int(choice.code[0]),
                  choice.point, detach(choice.point)[0], tangent(choice.point)[0])  # fmt: skip


def plot_case(case, ax=None, title=None, tangents=True):
    """The scene, the probes, the pair, the bracket, the tangent lines and the chosen point."""
    segments = np.stack([detach(case.geom.seg_a), detach(case.geom.seg_b)], axis=1)
    moving = np.flatnonzero(
        np.any(tangent(case.geom.seg_a) != 0, axis=1) | np.any(tangent(case.geom.seg_b) != 0, axis=1)
    )
    return plot_probes(
        segments, ORIGIN, case.ends, case.prim, pair=case.pair, bracket=case.bracket,
        point=case.point if case.code >= 0 else None, tangents=case.tangents if tangents else (),
        moving=moving, ax=ax, title=title,
    )  # fmt: skip


near_left = segment("near", [-1.0, 1.0], [0.0, 1.0])
occluder = probe([near_left, WALL], "near.translate.x")
print("probe film coordinates:", OFFSETS)
print("what each probe sees (0 near, 1 wall):", occluder.shape)
print("hit points:", np.round(occluder.ends, 12).tolist())

# %%
# check: the probes hit where the geometry says, (t Y, Y) on the line y = Y: the occluder (Y = 1) left of
# its end t = 0, the wall (Y = 2) right of it (rounding tolerance TOL)
assert occluder.shape.tolist() == [0, 0, 1, 1]
expected_ends = [[-0.3, 1.0], [-0.1, 1.0], [0.2, 2.0], [0.6, 2.0]]
assert np.allclose(occluder.ends, expected_ends, rtol=0.0, atol=TOL)

# %% [markdown]
# ## 2. Steps 1 and 3: the pair and the occlusion test
#
# Probe 0 sees the occluder; the last probe that sees something else is probe 3 (the wall), so
# the pair is (0, 3). Probes 1 and 2 are adjacent and see different shapes: they *bracket* the
# occluder's end. Both of the pair hit, so the tangent lines decide. With $o = (0, 0)$,
# $p_0 = (-0.3, 1)$, $p_1 = (0.6, 2)$ and normals $n_0 = n_1 = \pm(0, 1)$ (the products below do
# not depend on the sign):
#
# - line 0 ($y = 1$): $\bigl(n_0\cdot(p_1 - p_0)\bigr)\bigl(n_0\cdot(o - p_0)\bigr) = (1)(-1) = -1 <
#   0$:
#   it separates $p_1$ from $o$, so the occluder occludes the wall;
# - line 1 ($y = 2$): $\bigl(n_1\cdot(p_0 - p_1)\bigr)\bigl(n_1\cdot(o - p_1)\bigr) = (-1)(-2) = 2 >
#   0$:
#   the wall does not occlude the occluder.
#
# Exactly one occludes (step 3): the point is on the occluder, probe 0's shape, and of its
# hits the one next to the switch, probe 1's $(-0.1, 1)$. It is attached to the moving segment,
# so $dp/d\theta = (1, 0)$. We compute the two products from the attached hit points and normals:

# %%
(p0, n0), (p1, n1) = occluder.tangents
line0 = (n0 @ (p1 - p0)) * (n0 @ (ORIGIN - p0))
line1 = (n1 @ (p0 - p1)) * (n1 @ (ORIGIN - p1))
print(f"pair {occluder.pair}, bracket {occluder.bracket}; line 0: {line0:+.3f}, line 1: {line1:+.3f}")
print(f"chosen: {CHOSEN[occluder.code]}, point {occluder.point}, dp/dθ = {occluder.velocity}")

# %%
# check: the pair, the bracket and both products are the hand-derived ones, and the library chose probe 1's
# hit on the occluder, moving with it (rounding tolerance TOL)
assert np.allclose([p0, p1], [expected_ends[0], expected_ends[3]], rtol=0.0, atol=TOL)
assert occluder.pair == (0, 3) and occluder.bracket == (1, 2)
assert abs(line0 - -1.0) <= TOL and abs(line1 - 2.0) <= TOL
assert occluder.code == 0
assert np.allclose(occluder.point, [-0.1, 1.0], rtol=0.0, atol=TOL)
assert np.allclose(occluder.velocity, [1.0, 0.0], rtol=0.0, atol=TOL)

# %% [markdown]
# The figure: the occluder (thick: it moves), the wall, the four probes in the colour of what they
# hit with the pair thick, the bracket shaded, the two tangent lines dotted and the chosen point.

# %%
plot_case(occluder, title="step 3: the occluder occludes the wall")

# %% [markdown]
# ## 3. Step 2: only one of the pair hits
#
# Without the wall the probes right of the occluder's end escape. A miss counts as "no shape", so
# the pair is still (0, 3), and only probe 0 hits: its shape is followed (step 2), at the hit next
# to the switch, $(-0.1, 1)$. Mirrored, with the occluder from $(0, 1)$ to $(1, 1)$, probes 0 and 1
# escape and only the partner hits: step 2 again, the partner's shape, its hit next to the switch, probe 2's
# $(0.1, 1)$.

# %%
near_right = segment("near", [0.0, 1.0], [1.0, 1.0])
alone = {"only probe 0 hits": probe([near_left], "near.translate.x"),
         "only the partner hits": probe([near_right], "near.translate.x")}  # fmt: skip
fig = plot_grid(2, titles=list(alone))
for ax, case in zip(fig.axes, alone.values(), strict=True):
    plot_case(case, ax=ax)
fig

# %%
# check: step 2 takes probe 0's shape at probe 1's hit (-0.1, 1), then the partner's at probe 2's
# hit (0.1, 1), both moving with the occluder (rounding tolerance TOL)
first, second = alone.values()
assert first.shape.tolist() == [0, 0, -1, -1] and second.shape.tolist() == [-1, -1, 0, 0]
assert (first.code, second.code) == (0, 1)
assert np.allclose([first.point, second.point], [[-0.1, 1.0], [0.1, 1.0]], rtol=0.0, atol=TOL)
assert np.allclose([first.velocity, second.velocity], [[1.0, 0.0], [1.0, 0.0]], rtol=0.0, atol=TOL)

# %% [markdown]
# ## 4. Step 3 again: the occluder wins whichever probe hit it
#
# Put the occluder on the right, from $(0, 1)$ to $(1, 1)$, in front of the wall: now probe 0 sees
# the wall and the partner (probe 3) the occluder. By the same two products with the roles
# swapped, line 1 ($y = 1$) separates $p_0 = (-0.6, 2)$ from $o$ and line 0 ($y = 2$) does not,
# so the partner's shape is followed (step 3), at probe 2's hit $(0.1, 1)$. Side by side with
# section 2's scene:

# %%
occluders = {
    "step 3, probe 0 on the occluder": occluder,
    "step 3, the partner on the occluder": probe([near_right, WALL], "near.translate.x"),
}
fig = plot_grid(2, titles=list(occluders))
for ax, case in zip(fig.axes, occluders.values(), strict=True):
    plot_case(case, ax=ax)
fig

# %%
# check: whichever probe hit it, the point is on the occluder, next to the switch (rounding tolerance TOL)
swapped = occluders["step 3, the partner on the occluder"]
assert swapped.shape.tolist() == [1, 1, 0, 0] and swapped.pair == (0, 3) and swapped.code == 1
assert np.allclose(swapped.point, [0.1, 1.0], rtol=0.0, atol=TOL)
assert np.allclose(swapped.velocity, [1.0, 0.0], rtol=0.0, atol=TOL)

# %% [markdown]
# ## 5. Steps 4 and 5: nearly parallel lines, and the corner
#
# When neither tangent line separates the other hit from the origin, both surfaces are seen up to
# where they meet, and the point to follow is that meeting point. Take a roof seen from below:
# `left` from $(-1, 1)$ to $(0, 2)$ (the line $y = x + 2$) and `right` from $(0, 2)$ to $(1, 1)$ (the
# line $y = 2 - x$), and move `right` along $x$. The probe at film coordinate $t$ hits `left` where
# $y = t y + 2$, at $y = 2/(1 - t)$, and `right` at $y = 2/(1 + t)$. Neither line separates the other
# hit from $o$, the normals $(\mp 1, 1)/\sqrt2$ are perpendicular, so step 5 intersects the lines:
# $y = x + 2$ and $y = 2 - (x - \theta)$ meet at $(\theta/2, 2 + \theta/2)$, the corner $(0, 2)$
# moving with $dp/d\theta = (1/2, 1/2)$ — the derivative of the intersection of two *moving*
# lines, recomputed from the attached points and normals.
#
# Lines that are nearly parallel meet far away or at a badly conditioned point (a small error in
# either normal moves it far along the lines), so above $|n_0\cdot n_1| > 0.99$ step 4 falls back
# to probe 0's shape. `west` from $(-1, 3)$ to $(0, 3)$
# and `east` from $(0, 3)$ to $(1, 2.95)$ have $|n_0\cdot n_1| = 1/\sqrt{1 + 0.05^2} = 0.99875$; neither
# occludes the other, so the point is `west`'s hit next to the switch, probe 1's
# $(-0.1 \cdot 3, 3) = (-0.3, 3)$, moving with `west` (`west.translate.x`).

# %%
roof = probe([segment("left", [-1.0, 1.0], [0.0, 2.0]), segment("right", [0.0, 2.0], [1.0, 1.0])],
             "right.translate.x")  # fmt: skip
flat = probe([segment("west", [-1.0, 3.0], [0.0, 3.0]), segment("east", [0.0, 3.0], [1.0, 2.95])],
             "west.translate.x")  # fmt: skip
(_, n_west), (_, n_east) = flat.tangents
print(f"roof: {CHOSEN[roof.code]}, point {roof.point}, dp/dθ {roof.velocity}")
print(
    f"west/east: |n0·n1| = {abs(n_west @ n_east):.5f} > {PARALLEL}: {CHOSEN[flat.code]}, point {flat.point}"
)
fig = plot_grid(
    2, titles=["step 5: a roof seen from below, the corner", "step 4: nearly parallel, probe 0's shape"]
)
plot_case(roof, ax=fig.axes[0])
plot_case(flat, ax=fig.axes[1])
fig

# %%
# check: the roof's corner (0, 2) moving at (1/2, 1/2) (step 5), and west's hit (-0.3, 3) (step 4) with
# |n0·n1| = 1/sqrt(1 + 0.05²) (rounding tolerance TOL)
assert roof.pair == (0, 3) and roof.code == 2
assert np.allclose(roof.point, [0.0, 2.0], rtol=0.0, atol=TOL)
assert np.allclose(roof.velocity, [0.5, 0.5], rtol=0.0, atol=TOL)
assert abs(abs(n_west @ n_east) - 1.0 / np.sqrt(1.0 + 0.05**2)) <= TOL and flat.code == 0
assert np.allclose(flat.point, [-0.3, 3.0], rtol=0.0, atol=TOL)
assert np.allclose(flat.velocity, [1.0, 0.0], rtol=0.0, atol=TOL)

# %% [markdown]
# ## 6. The hit next to the switch, and bisection
#
# Why the hit next to the switch, and not probe 0's? An attached point moves with its segment,
# but only a translation moves every point of a segment like its end. Let the occluder end at
# $x = 0.24$, in front of the wall, and *rotate* it about its centre $c = (-0.38, 1)$
# (`near.rotate`). A point $(x, 1)$ of it moves with $d(x, y)/d\theta = (0, x + 0.38)$, so its
# film coordinate $t = x/y$ moves at
#
# $$
# \frac{dt}{d\theta} = \frac{\dot x\, y - x\, \dot y}{y^2} = -x\,(x + 0.38),
# $$
#
# $-0.1488$ at the end $x = 0.24$, the silhouette. The error of following the point at $x$ instead is
# $-x(x + 0.38) + 0.24 \cdot 0.62 = (x - 0.24)(x + 0.62)$: first order in its distance from the
# silhouette. Probe 0's hit ($x = -0.3$) would move at $+0.024$, the wrong sign; the hit next to the
# switch, probe 2's ($x = 0.1$), at $-0.048$. Bisection (`refine` steps) traces the middle of the
# bracket and keeps the half that still contains the switch: the bracket $(0.1, 0.3)$ becomes
# $(0.2, 0.3)$ (the ray at $0.2$ hits the occluder), then $(0.2, 0.25)$ (the ray at $0.25$ hits the
# wall), and the point $x = 0.2$ moves at $-0.116$. The library's default is `refine=2`.

# %%
near_rotating = segment("near", [-1.0, 1.0], [0.24, 1.0])
rotating = {k: probe([near_rotating, WALL], "near.rotate", refine=k) for k in (0, 2)}


def film_speed(p):
    """dt/dθ of the film coordinate of attached points p (Dual, (n, 2))."""
    return tangent(film_coordinate(rotating[0].geom, p - rotating[0].geom.cam_o))


geom = rotating[0].geom
edge_speed = film_speed(geom.seg_b[:1])[0]  # the occluder's end, the silhouette
probe0_speed = film_speed(attached_points(geom, rotating[0].prim[:1], rotating[0].coord[:1])[0])[0]
chosen_speed = {k: film_speed(c.attached)[0] for k, c in rotating.items()}
print(f"silhouette {edge_speed:+.4f}; probe 0's hit {probe0_speed:+.4f}; ", end="")
print(
    ", ".join(
        f"chosen with refine={k} {s:+.4f} at x = {rotating[k].point[0]:.2f}" for k, s in chosen_speed.items()
    )
)

# %%
# check: the speeds are -x (x + 0.38) at x = 0.24 (the end), -0.3 (probe 0), 0.1 (next to the switch) and
# 0.2 (bisected) (rounding tolerance TOL), and each is closer to the silhouette's than the one before
assert rotating[0].code == rotating[2].code == 0
assert np.allclose([rotating[0].point, rotating[2].point], [[0.1, 1.0], [0.2, 1.0]], rtol=0.0, atol=TOL)
speeds = np.array([edge_speed, probe0_speed, chosen_speed[0], chosen_speed[2]])
assert np.allclose(speeds, [-x * (x + 0.38) for x in (0.24, -0.3, 0.1, 0.2)], rtol=0.0, atol=TOL)
assert abs(probe0_speed - edge_speed) > abs(chosen_speed[0] - edge_speed) > abs(chosen_speed[2] - edge_speed)

# %% [markdown]
# The bracket $(0.1, 0.3)$ between probes 2 and 3 contains the occluder's end; bisection moved the
# followed point from probe 2's hit to $x = 0.2$, inside it:

# %%
fig = plot_grid(2, titles=["the hit next to the switch (refine=0)", "after two bisection steps (refine=2)"])
for ax, k in zip(fig.axes, (0, 2), strict=True):
    plot_case(rotating[k], ax=ax, tangents=False)
fig

# %% [markdown]
# Bisection halves the distance to the silhouette with each step, but never removes it. On the
# film the library takes the last step: the occluder is a segment, the silhouette is its end, and
# that end's image $t = 0.24$ lies inside the probes' span $(-0.3, 0.3)$. Given the primitive the
# probes followed, `film_shape_end` names the endpoint at that end of its shape's image (an index
# into the segments' first ends, then their second ends), and the film transform follows the
# endpoint itself, which moves like the silhouette under every motion. (A shape whose *whole*
# image lies inside the span has both ends followed at once, by a map that stretches between
# them: `film_inner_shape`, on the theory page.)

# %%
end = int(film_shape_end(geom.detached(), OFFSETS[None], np.zeros(1, dtype=int))[0])
n_seg = geom.n_seg
endpoint = (geom.seg_a if end < n_seg else geom.seg_b)[end % n_seg : end % n_seg + 1]
end_point_speed = film_speed(endpoint)[0]
print(f"followed endpoint {end}: {detach(endpoint)[0]}, film speed {end_point_speed:+.4f}")

# %%
# check: the endpoint is the occluder's second end (0.24, 1), and it moves on the film at the silhouette's
# speed -0.24 (0.24 + 0.38) = -0.1488, to rounding
assert end == n_seg + 0
assert np.allclose(detach(endpoint)[0], [0.24, 1.0], rtol=0.0, atol=TOL)
assert abs(end_point_speed - edge_speed) <= TOL

# %% [markdown]
# ## 7. Step 6: nothing to follow, the identity
#
# When every probe hits the same primitive, or none hits, no discontinuity is in sight and the
# transform stays the identity (code -1). Following the hit anyway would be unbiased too, but it
# would add the kernel weight's derivative, pure variance, wherever a surface moves in the image.
# The wall alone, and the same wall behind the camera (every probe escapes):

# %%
behind = segment("wall", [-2.0, -2.0], [2.0, -2.0])
nothing = {
    "one primitive in sight": probe([WALL], "wall.translate.x"),
    "nothing in sight": probe([behind], "wall.translate.x"),
}
fig = plot_grid(2, titles=list(nothing))
for ax, case in zip(fig.axes, nothing.values(), strict=True):
    plot_case(case, ax=ax)
fig

# %%
# check: both are the identity (code -1, no pair): every probe on the wall, and no probe on anything
seen, unseen = nothing.values()
assert seen.shape.tolist() == [0, 0, 0, 0] and unseen.shape.tolist() == [-1, -1, -1, -1]
assert seen.code == unseen.code == -1 and seen.pair is None and unseen.pair is None

# %% [markdown]
# ## 8. The consequence: a pixel derivative
#
# The choice is made per sample, and the translation it defines is applied inside the sample's
# kernel. Here it is for one pixel, step by step as `ReparamTransforms.camera` does it, with the
# library's functions. The scene of section 2 becomes an image: the wall emits radiance 1, the
# occluder, black, ends at $x_e = 0.03$ ($t_e = 0.03$, moving at $t_e' = 1$ under
# `near.translate.x`). Eight pixels cover $t \in [-0.4, 0.4]$ (width $\Delta t = 0.1$); pixel 4 is
# centred on $0.05$. With a Gaussian pixel filter $k_4$ (standard deviation $\Delta t / 2$),
# $I_4 = \int k_4(t)\, L(t)\, dt$ with $L = 0$ left of $t_e$ and $1$ right of it, so
#
# $$
# \frac{dI_4}{d\theta} = -k_4(t_e)\, t_e' .
# $$
#
# (The tent filter would do as well, but its logarithmic derivative grows like one over the
# distance to its support's end: a heavy tail that makes the standard error unreliable.)
#
# Per sample: $t \sim k_4$; the kernel centre $\omega = t + \sigma z$ with the library's film kernel
# ($\sigma = 0.4\,\Delta t / \sqrt 2$); probes at
# $\omega + \sigma \cdot 3 \cdot (-1, -\tfrac13, \tfrac13, 1)$; the chosen point $p$ (with `refine=2`);
# the translation $T(t) = t + t_p(\theta) - t_p(\theta_0)$ with
# $t_p$ the film coordinate of $p$, or the identity where nothing was chosen; the estimate
# $L(T t)\, \frac{k_4(T t)}{k_4(t)}\, \frac{k(T t, \omega)}{k(t, \omega)}$, whose value is $L(t)$.
#
# The estimator is slightly biased, by a predicted amount: a kernel centre farther than $3\sigma$
# from the edge has probes that do not bracket it, yet its kernel still reaches the edge. That
# misses the fraction $\varepsilon = 2(1 - \Phi(3)) = 0.27\,\%$ of the edge's term, so the estimator's
# mean is $(1 - \varepsilon)$ times the closed form.
#
# To see what the heuristic buys, the same samples are also evaluated following the *partner's*
# hit, the wall, where the heuristic's occlusion test picked the occluder.

# %%
pixel_scene = {
    "name": "one_edge",
    "camera": {"position": [0.0, 0.0], "direction": [0.0, 1.0], "fov": float(2.0 * np.arctan(0.4)),
               "pixels": 8, "filter": "gaussian"},
    "sky": 0.0,
    "shapes": [segment("near", [-1.0, 1.0], [0.03, 1.0], albedo=0.0),
               segment("wall", [-2.0, 2.0], [2.0, 2.0], albedo=0.0, emission=1.0)],
}  # fmt: skip
N, PIXEL, T_EDGE = 200_000, 4, 0.03
scene = load_scene(pixel_scene)
geom = build_state(scene, "near.translate.x", variable(0.0))
geom0 = geom.detached()
width, centre = scene.camera.pixel_width, scene.camera.pixel_centers()[PIXEL]
kappa_film = default_kappa_film(width)
sigma = 1.0 / np.sqrt(kappa_film)


def trace(rows, t):
    hits = cast(geom0, ORIGIN, film_direction(geom0, t))
    return hits.prim, hits.coord


t = sample_filter("gaussian", stream(SEED, "film").random(N), centre, width)
omega = t + sigma * stream(SEED, "kernel").standard_normal(N)
probes = omega[:, None] + sigma * SPREAD * np.linspace(-1.0, 1.0, PROBES)
prim, coord = (a.reshape(N, PROBES) for a in trace(None, probes.ravel()))
origins, centres = np.broadcast_to(ORIGIN, (N, 2)), film_direction(geom0, omega)
choice = select_points(geom, origins, prim, coord, centres, probes, trace, refine=2)


def pixel_estimates(point, ok):
    """Per-sample L(T t) k_4(T t)/k_4(t) k(T t, ω)/k(t, ω), following the points ``point`` where ``ok``."""
    v = np.where(ok[:, None], point - geom.cam_o, detach(geom.cam_f))
    moved = t + translation_offset(film_coordinate(geom, v), ok)  # T(t) = t + t_p(θ) - t_p(θ0)
    weight = filter_value("gaussian", moved, centre, width) / filter_value("gaussian", t, centre, width)
    weight = weight * unit_weight(-0.5 * kappa_film * (moved - omega) ** 2)  # k(Tt, ω)/detach, Sec. 4.2
    hits = cast(geom0, ORIGIN, film_direction(geom0, detach(moved)))
    radiance = np.where(hits.prim >= 0, detach(geom.emission)[np.maximum(hits.prim, 0)], geom.sky)
    return radiance * weight


chosen = pixel_estimates(choice.point, choice.ok)
# probe 3's hit: on the wall wherever the probes bracket t_e
wall_point, _ = attached_points(geom, prim[:, -1], coord[:, -1])
wall = pixel_estimates(wall_point, choice.ok & (prim[:, -1] == 1))
closed = -float(filter_value("gaussian", T_EDGE, centre, width))  # -k_4(t_e) t_e'
epsilon = 2.0 * stats.norm.sf(3.0)
d_chosen = tangent(chosen)
mean, stderr = d_chosen.mean(), d_chosen.std(ddof=1) / np.sqrt(N)
counts = np.bincount(choice.code + 1, minlength=4).tolist()
print(f"samples per choice (nothing, probe 0's shape, the partner's, the corner): {counts}")
print(f"dI_4/dθ following the chosen points: {mean:.4f} ± {stderr:.4f}")
print(f"closed form -k_4(t_e) = {closed:.4f}; predicted mean (1 - ε) closed = {(1 - epsilon) * closed:.4f}")
print(f"following the wall instead: {tangent(wall).mean():.4f}")

# %%
# check: following the chosen points, the derivative matches the predicted mean (1 - ε) · closed form within
# z standard errors (i.i.d. samples, two-sided, level 1e-3). The bias ε · |closed| = 0.02 is below the
# resolution z · stderr here; with 2·10^7 samples (40 seeds) the mean was -7.336 ± 0.006, 1.6 standard
# errors from the prediction -7.346 and 4.8 from the closed form -7.365. The primal is L(t), the naive
# estimate, bit for bit; following the wall, which does not move, gives exactly 0: the derivative is lost
z = normal_quantile(1.0 - sidak(1e-3, 1))
assert abs(mean - (1.0 - epsilon) * closed) <= z * stderr
assert abs(epsilon * closed) < z * stderr
radiance_naive = np.where(cast(geom0, ORIGIN, film_direction(geom0, t)).prim == 1, 1.0, 0.0)
assert np.array_equal(detach(chosen), radiance_naive)
assert np.all(tangent(wall) == 0.0) and abs(mean) > 50 * stderr

# %% [markdown]
# The library's `reparam` does exactly this for every pixel, with its own random numbers, and its
# standard errors come from 16 batches. Its pixel 4 against the same closed form:

# %%
library = fl.render_gradient(scene, "near.translate.x", method="reparam", spp=8192, seed=SEED)
print(f"library pixel {PIXEL}: {library.derivative[PIXEL]:.4f} ± {library.derivative_stderr[PIXEL]:.4f}")

# %%
# check: within t standard errors (16 batches, 15 degrees of freedom, two-sided, level 1e-3) of the predicted
# mean (1 - ε) · closed form
t_level = stats.t.ppf(1.0 - sidak(1e-3, 1) / 2.0, library.batches - 1)
assert abs(library.derivative[PIXEL] - (1.0 - epsilon) * closed) <= t_level * library.derivative_stderr[PIXEL]

# %% [markdown]
# **Explore.** How many probes does the rule need, and how far from the occluder's end may the
# sample be? `flatland.widgets.probes_view` traces section 1's scene with the number of probes and
# the sample's film coordinate set by the sliders, and draws the choice. With two probes far from
# the end nothing brackets it, and the point chosen is on the wall, which does not move.
# (Open the notebook in Jupyter to move the sliders.)

# %%
explore_probes = explore(probes_view, probes=(2, 12, 4), offset=(-0.5, 0.5, 0.0))
explore_probes

# %%
# check: two sliders and the output; the default view chooses probe 1's hit on the occluder, as in section 2
assert len(explore_probes.children) == 3
assert "point (-0.10, 1.00), dp/dθ = 1.00" in probes_view(4).axes[0].get_title()

# %% [markdown]
# ## Summary
#
# A handful of probe rays per sample, traced inside the kernel, tell the reparameterization what
# to follow: probe 0 is paired with the last probe that sees another shape; a lone hit is used;
# of two hits the occluder wins, by the tangent-line test; two surfaces that do not occlude each
# other are followed at their corner (or at probe 0's hit when the lines are nearly parallel); and
# nothing in sight leaves the identity. The hit used is the one next to the switch, refined by
# bisection, because an attached point moves like the silhouette only to first order in its
# distance from it. Choosing wrong loses the derivative: following the static wall gave exactly 0
# where the occluder's edge gave the closed form.
#
# The occlusion test treats each tangent line as infinite, and one translation follows one
# motion: tutorial 9 shows where these assumptions fail (overlapping occluders, a small blocker
# in front of a hard-edged emitter) and measures the bias.
