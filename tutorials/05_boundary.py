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
# # 5. Boundary terms: edge sampling in flatland
#
# **What you will learn.**
#
# - how to add the missing term directly: boundary (edge) sampling in flatland, checked against
#   closed forms
# - what it costs, and why it is hard to carry over to 3D
#
# Naive differentiation returns the interior term of the Leibniz rule and drops the term of the
# moving discontinuities (tutorials 1 and 4). The direct remedy is to compute that term and add
# it (`docs/theory/leibniz.md`, `docs/theory/boundary.md`):
#
# $$
# \frac{dI}{d\theta} = \underbrace{\int \frac{\partial f}{\partial \theta}\,dx}_{\text{naive AD}}
# + \underbrace{\sum_c \bigl[f(c^-) - f(c^+)\bigr]\,c'(\theta)}_{\text{boundary term}} .
# $$
#
# This is what edge sampling does in 3D (Li et al. 2018): it samples points on the silhouette
# edges and evaluates the jump across each. In flatland every integral the renderer computes is
# over an angle or a film coordinate, and its discontinuities are *points*: the directions toward
# segment endpoints and circle tangent points. They can be enumerated, so the boundary term is a
# finite sum, computed here in three steps, each checked against a closed form:
#
# 1. list the candidate discontinuities $c(\theta)$ with their velocities $c'$ (forward AD of
#    their position);
# 2. measure each jump $f(c^-) - f(c^+)$ by tracing two rays just beside $c$;
# 3. add the products to the naive interior term, at the camera and at every shading point.
#
# The running scene is a hard shadow: a floor lit by a segment emitter with *unfaded* ends, a
# segment occluder between them, and the parameter `occluder.translate.x`. The first cell
# imports the library and fixes the seed.

# %%
# %matplotlib inline
import time

import numpy as np
from scipy import stats

import flatland as fl
from flatland import detach, tangent, variable
from flatland.core.stats import sidak
from flatland.integrator import incident
from flatland.plotting import tutorials as ptu
from flatland.state import build_state
from flatland.tracing import cast, direction, film_coordinate, silhouette_angles

SEED = 20191117
PARAM = "occluder.translate.x"
LIGHT = 4.0  # the emitter's radiance
scene = fl.load_scene(
    {
        "name": "hard_shadow",
        "camera": {"position": [-2.5, 1.6], "direction": [2.7, -1.6], "fov": 1.0, "pixels": 32},
        "sky": 0.0,
        "shapes": [
            {"name": "floor", "type": "segment", "points": [[-3.0, 0.0], [3.0, 0.0]], "albedo": 0.8},
            {"name": "occluder", "type": "segment", "points": [[-0.4, 0.8], [0.4, 0.8]], "albedo": 0.5},
            {"name": "light", "type": "segment", "points": [[-0.6, 2.0], [0.6, 2.0]], "emission": LIGHT,
             "one_sided": True},
        ],
        "parameters": [PARAM],
    }
)  # fmt: skip
geom = build_state(scene, PARAM, variable(0.0))  # the scene as arrays; θ-dependent ones are Duals

# %% [markdown]
# ## 1. Where can the integrand jump?
#
# Visibility changes only where a ray grazes a shape's end: a segment endpoint, or a point where
# a ray is tangent to a circle. `silhouette_angles(geom, origin)` returns the angle of every such
# candidate seen from an origin, as a `Dual` whose tangent is its angular velocity. Seen from the
# camera, the film coordinate of a direction $v$ is $t = (v\cdot r)/(v \cdot f)$ with $f$ the
# forward and $r$ the right vector (`film_coordinate`), so $t_c'$ follows by the chain rule,
# inside the `Dual` arithmetic.
#
# By hand: an endpoint $p$ translated along $x$ has $v' = (1, 0)$, so
# $t' = \bigl(r_x\,(v\cdot f) - (v \cdot r)\, f_x\bigr)/(v\cdot f)^2$. Only the occluder's two ends
# move; the other four candidates must have velocity exactly zero.

# %%
names = [s.name for s in scene.shapes for _ in s.points]
phi_cam, exists = silhouette_angles(geom, geom.cam_o)
t_c = film_coordinate(geom, direction(phi_cam[0]))
f, r = detach(geom.cam_f), detach(geom.cam_r)
v = detach(geom.vertices) - detach(geom.cam_o)
by_hand = np.where([n == "occluder" for n in names], (r[0] * (v @ f) - (v @ r) * f[0]) / (v @ f) ** 2, 0.0)
half = scene.camera.half_width
print(f"{'vertex':>10} {'t':>8} {'in view':>8} {'dt/dθ (AD)':>11} {'by hand':>9}")
for name, t, dt, h in zip(names, detach(t_c), tangent(t_c), by_hand, strict=True):
    print(f"{name:>10} {t:8.3f} {abs(t) <= half!s:>8} {dt:11.5f} {h:9.5f}")

# %%
# check: the velocities from forward AD equal the hand-derived ones (1e-12), the static shapes' candidates
# do not move at all, and both moving ends are in view
assert np.all(exists) and np.allclose(tangent(t_c), by_hand, rtol=0.0, atol=1e-12)
moving = np.array([n == "occluder" for n in names])
assert np.all(tangent(t_c)[~moving] == 0.0) and np.all(np.abs(detach(t_c)[moving]) <= half)

# %% [markdown]
# ## 2. How big is each jump? One shading integral
#
# At a floor point $x$ with normal $n = (0, 1)$ the renderer estimates the irradiance
# $E(x) = \int L_i(x, \varphi) \max(0, \cos(\varphi - \varphi_n))\, d\varphi$. Here $L_i = 4$
# toward the visible part of the light and 0 elsewhere. With the angles $\varphi$ measured from the
# $x$ axis, $\cos(\varphi - \varphi_n) = \sin\varphi$ and a visible interval $[\varphi_1, \varphi_2]$
# contributes $L\,(\cos\varphi_1 - \cos\varphi_2)$ (`docs/theory/radiometry.md`). The visible intervals are
# the light's interval minus the occluder's, which moves with $\theta$; written with `Dual`
# arithmetic this closed form is a smooth function of $\theta$, and its tangent is the exact $dE/d\theta$.
#
# We pick $x = (0.5, 0)$, in the penumbra: the occluder's right end hides part of the light.

# %%
x = np.array([0.5, 0.0])


def angle(p):
    """Angle of the point p seen from x."""
    return np.arctan2(p[1] - x[1], p[0] - x[0])


def irradiance_closed_form(theta):
    """E(x) with the occluder moved by theta (a float or a Dual): L × Σ (cos φ1 - cos φ2)."""
    light = [angle(np.array([0.6, 2.0])), angle(np.array([-0.6, 2.0]))]  # [φ1, φ2], counter-clockwise
    ends = [
        angle(np.stack([0.4 + theta, 0.8 + 0.0 * theta])),
        angle(np.stack([-0.4 + theta, 0.8 + 0.0 * theta])),
    ]
    start = np.minimum(np.maximum(ends[0], light[0]), light[1])  # occluder's interval clipped to the light's
    stop = np.maximum(np.minimum(ends[1], light[1]), light[0])
    return LIGHT * ((np.cos(light[0]) - np.cos(start)) + (np.cos(stop) - np.cos(light[1])))


E = irradiance_closed_form(variable(0.0))
h = 1e-5
central = (irradiance_closed_form(h) - irradiance_closed_form(-h)) / (2 * h)
sampled = fl.irradiance(scene, x, (0.0, 1.0), n=65536, seed=SEED)  # the renderer's estimate of E alone
print(f"closed form: E = {detach(E):.6f}, dE/dθ = {tangent(E):.6f} (central difference {central:.6f})")
print(f"fl.irradiance: E = {sampled.value:.6f} ± {sampled.value_stderr:.6f}")

# %%
# check: the closed form is the renderer's E (its estimate lies within t standard errors: 16 batches, so 15
# degrees of freedom, two-sided 99.9 %), and the tangent is its derivative (central difference, 1e-6)
assert abs(sampled.value - detach(E)) <= stats.t.ppf(1 - 0.001 / 2, 15) * sampled.value_stderr
assert abs(central - tangent(E)) < 1e-6

# %% [markdown]
# Now the boundary term by hand. The candidates seen from $x$ are the six vertices again, with
# angles $\varphi_c(\theta)$ as `Dual`s. For each we trace one ray at $\varphi_c - \epsilon$ and one at
# $\varphi_c + \epsilon$ on the detached geometry (`cast`, skipping the floor the point lies on),
# read the incident radiance (`incident`: the emission of what the ray hits), and weight by the
# cosine. The term is $\sum_c [f(c^-) - f(c^+)]\,\varphi_c'$; the interior term is zero here
# ($L_i$ and the cosine do not depend on $\theta$ at a fixed angle), so the sum must be $dE/d\theta$.

# %%
geom0 = geom.detached()
floor = 0  # primitive index of the floor segment: rays leaving x skip it
phi_x, exists_x = silhouette_angles(geom, x)
phi0 = detach(phi_x[0])
eps = 1e-7


def f_beside(phi):
    """The integrand L_i cos at angles phi, traced on the detached geometry."""
    d = direction(phi)
    hits = cast(geom0, np.broadcast_to(x, d.shape), d, np.full(phi.size, floor))
    return incident(geom0, x, d, hits)[0] * np.maximum(np.sin(phi), 0.0)


jump = f_beside(phi0 - eps) - f_beside(phi0 + eps)
terms = jump * tangent(phi_x[0])
print(f"{'vertex':>10} {'angle°':>8} {'jump':>8} {'dφ/dθ':>8} {'term':>9}")
for name, a, j, dphi, term in zip(names, np.degrees(phi0), jump, tangent(phi_x[0]), terms, strict=True):
    print(f"{name:>10} {a:8.2f} {j:8.4f} {dphi:8.4f} {term:9.4f}")
library = {
    m: fl.irradiance(scene, x, (0.0, 1.0), PARAM, method=m, n=4096, seed=SEED) for m in ("naive", "boundary")
}
print(f"sum of terms {terms.sum():.6f};  fl.irradiance: naive {library['naive'].derivative}, "
      f"boundary {library['boundary'].derivative:.6f}")  # fmt: skip

# %%
# check: only the occluder's right end (inside the light's interval) carries a term; the sum equals the
# closed-form dE/dθ, and so does the library's boundary method (both to 1e-6 relative: the rays beside
# each candidate sit 1e-7 rad away); the naive method returns the interior term, exactly 0
right_end = names.index("occluder") + 1
assert np.all(exists_x) and np.count_nonzero(terms) == 1 and terms[right_end] != 0.0
assert abs(terms.sum() - tangent(E)) <= 1e-6 * abs(tangent(E))
assert abs(library["boundary"].derivative - tangent(E)) <= 1e-6 * abs(tangent(E))
assert library["naive"].derivative == 0.0

# %% [markdown]
# The light's right end jumps (from nothing to $L\cos$) but does not move; its left end is
# hidden behind the occluder, so the traced rays see the occluder on both sides and nothing
# jumps there. The occluder's left end moves but lies outside the light's interval, with
# darkness on both sides. The floor's ends lie at the horizon, where the cosine is zero. Of the
# six candidates, one carries the whole derivative.
#
# ## 3. The whole image
#
# `render_gradient(..., method="boundary")` does the same everywhere: the naive estimator for the
# interior term, plus, at every shading point of every sample, the jump terms of its irradiance,
# plus, at the camera, $\sum_c k_j(t_c)\,[L(t_c^-) - L(t_c^+)]\,t_c'$ for every pixel $j$. The
# camera-side jumps of the full radiance (emission plus shaded light) are Monte Carlo estimates:
# each side of a candidate is shaded with the same random numbers, so a candidate hidden behind
# something has a jump of exactly zero. We compare it with central finite differences
# (`h = 0.01`, common random numbers, 16 times the samples, because they are noisier).

# %%
start = time.perf_counter()
image = fl.render(scene, spp=256, seed=SEED)
gradients = {
    "naive": fl.render_gradient(scene, PARAM, method="naive", spp=256, seed=SEED),
    "boundary": fl.render_gradient(scene, PARAM, method="boundary", spp=256, seed=SEED),
    "finite differences": fl.render_gradient(
        scene, PARAM, method="finite_difference", spp=4096, seed=SEED + 1, h=0.01
    ),
}
boundary, fd = gradients["boundary"], gradients["finite differences"]
t32 = stats.t.ppf(1 - sidak(1e-3, 32) / 2, boundary.batches - 1)
z_naive = np.abs(gradients["naive"].derivative - fd.derivative) / np.maximum(fd.derivative_stderr, 1e-300)
errors = {name: round(g.error_vs(boundary), 3) for name, g in gradients.items()}
print(f"{time.perf_counter() - start:.1f} s;  relative error vs boundary: {errors}")
print(f"pixels where naive is off by more than the t quantile {t32:.2f}: {np.sum(z_naive > t32)}")

# %%
# check: boundary and finite differences agree pixel by pixel within t standard errors (15 degrees of
# freedom, two-sided, family-wise 1e-3 Šidák-corrected over 32 pixels) plus the 1 % resolution of finite
# differences with common random numbers; the naive derivative is off by more than that quantile in at
# least 10 pixels (measured: 16, the silhouette and both shadow edges)
tolerance = (
    t32 * np.hypot(boundary.derivative_stderr, fd.derivative_stderr)
    + 0.01 * np.abs(boundary.derivative).max()
)
assert np.all(np.abs(boundary.derivative - fd.derivative) <= tolerance)
assert np.sum(z_naive > t32) >= 10

# %% [markdown]
# Left, the scene: the camera's view in cyan, the light in gold, the occluder and its motion in
# green. The occluder covers pixels 8 to 11 (its lit top is the white pixel); to its left lies the floor
# in front of it, to its right its shadow on the floor, then the lit floor. Moving the occluder
# right moves its two silhouettes and both penumbrae of its shadow, and the boundary method finds
# all four. The naive derivative is zero everywhere: a horizontal segment sliding along itself
# presents the same surface point to every camera ray, and the light reaching any fixed point
# changes only through visibility, so there is no interior term at all.

# %%
ptu.plot_gradient_panel(image, gradients, title=f"hard shadow: d/d {PARAM}", scene=scene, param=PARAM)

# %% [markdown]
# ## 4. What it costs, and why this does not carry over to 3D
#
# Every shading point considers every candidate: $V + 2C$ of them ($V$ vertices, $C$ circles),
# two rays each, on top of the two rays (one cosine sample, one emitter sample) of the shading
# estimate itself. The built-in scenes are small; the cost grows linearly with the number of
# vertices in view. We count the candidates of each built-in scene and time the two methods.

# %%
rows = []
for name in fl.list_scenes():
    s = fl.load_scene(name)
    vertices = sum(len(shape.points) for shape in s.shapes if shape.type != "circle")
    circles = sum(shape.type == "circle" for shape in s.shapes)
    g = build_state(s, s.parameters[0], variable(0.0))
    candidates = silhouette_angles(g, g.cam_o)[0].shape[1]
    seconds = {}
    for method in ("naive", "boundary"):
        start = time.perf_counter()
        fl.render_gradient(s, s.parameters[0], method=method, spp=64, seed=SEED)
        seconds[method] = time.perf_counter() - start
    rows.append((name, vertices, circles, candidates, seconds["boundary"] / seconds["naive"]))
print(f"{'scene':>14} {'V':>3} {'C':>3} {'candidates':>11} {'rays per shading point':>23} {'time ratio':>11}")
for name, vertices, circles, candidates, ratio in rows:
    print(f"{name:>14} {vertices:3d} {circles:3d} {candidates:11d} {2 + 2 * candidates:23d} {ratio:11.1f}")

# %%
# check: the candidates are exactly the vertices plus two tangent points per circle, in every scene
for _, vertices, circles, candidates, _ in rows:
    assert candidates == vertices + 2 * circles

# %% [markdown]
# In 3D the candidates are no longer points. Seen from a shading point, the discontinuities of
# the integrand over the sphere of directions are *curves*: the projections of the silhouette
# edges of every mesh (edges between a face turned toward the point and one turned away),
# clipped by whatever is in front of them. Edge sampling (Li et al. 2018) therefore samples
# points on silhouette edges, with a density, per shading point: it needs a data structure to find
# the silhouette edges seen from an arbitrary point, and its variance depends on how well that
# density matches the jumps. Reparameterization (tutorial 6, and `sphere3d` in tutorial 10) avoids
# finding the edges at all: it changes variables so that whatever edge is near a sample stops
# moving, using only the ordinary ray tracing the renderer already does. In flatland, where the
# enumeration is cheap and exact, `boundary` is the unbiased reference the other methods are
# judged against.
