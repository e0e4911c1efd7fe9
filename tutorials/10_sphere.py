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
# # 10. On the sphere: rotations, vMF kernels and Embree
#
# **What you will learn.**
#
# - the same code on the sphere: rotations instead of translations, von Mises–Fisher kernels, Embree
# - how hits are re-attached to θ, and the kernel's trade-off against a closed form on S²
#
# Everything so far lived in flatland, where directions are angles on the circle $S^1$. A real
# renderer integrates over the sphere of directions $S^2$ and traces rays against triangle meshes.
# The `sphere3d` package carries each idea over (Loubet et al. 2019, Sec. 4.1-4.2):
#
# | flatland (`import flatland as fl`) | sphere3d (`import sphere3d as s3`) |
# |---|---|
# | translation of an angle, $\varphi + \Delta$ | rotation $R(\theta)\,\omega$ with $R(\theta_0) = I$ |
# | von Mises kernel on $S^1$ | von Mises–Fisher kernel on $S^2$ |
# | segments and circles, numpy ray casting | triangle meshes traced by Embree |
# | hits re-attached to θ with `Dual`s | the same, with fixed barycentrics |
#
# and keeps the API: `render`, `render_gradient`, `irradiance`, `load_scene`, the method names,
# and the result types. This notebook first runs one function unchanged on both packages, then
# opens the three pieces that differ: the rotation, the vMF kernel and the Embree tracer, and
# ends with the kernel's bias/variance trade-off on a closed-form irradiance on $S^2$.

# %%
# %matplotlib inline
import time

import numpy as np
from scipy import special, stats

import flatland as fl
import sphere3d as s3
from flatland import detach, tangent, variable
from flatland.core.rng import stream
from flatland.core.stats import normal_quantile, sidak
from flatland.plotting import textbook as pt
from flatland.plotting import tutorials as ptu
from flatland.sampling import sample_von_mises
from sphere3d.rotation import Rotation, rotation_matrix
from sphere3d.sampling import sample_vmf
from sphere3d.state import build_state
from sphere3d.tracing import BruteForceTracer, attached_points

SEED = 20191117
PARAM = "occluder.translate.x"

# %% [markdown]
# ## 1. The same code on both packages
#
# One function: render the image, its derivative by the naive and the reparameterized methods,
# and a finite-difference reference (four times the samples, `h = 0.01`). The package is an
# argument; nothing else changes. Both packages have a scene called `silhouette` with a parameter
# `occluder.translate.x`: in flatland a polygon in front of an emitting backdrop, in sphere3d a
# box in front of a uniform sky. The sphere's image is rendered at 24 × 24 pixels to keep the
# notebook fast.


# %%
def differentiate(pkg, scene, param, spp):
    """The primal image and three derivative images of ``scene`` with package ``pkg``."""
    image = pkg.render(scene, spp=spp, seed=SEED)
    gradients = {
        m: pkg.render_gradient(scene, param, method=m, spp=spp, seed=SEED) for m in ("naive", "reparam")
    }
    gradients["finite differences"] = pkg.render_gradient(
        scene, param, method="finite_difference", spp=4 * spp, seed=SEED + 1, h=0.01
    )
    return image, gradients


sphere_scene = s3.load_scene("silhouette").to_dict()
sphere_scene["camera"].update(width=24, height=24)
results = {}
for pkg, scene in ((fl, "silhouette"), (s3, sphere_scene)):
    start = time.perf_counter()
    results[pkg.__name__] = differentiate(pkg, scene, PARAM, spp=256)
    image, gradients = results[pkg.__name__]
    errors = {m: round(g.error_vs(gradients["finite differences"]), 3) for m, g in gradients.items()}
    print(f"{pkg.__name__:>9}: film {image.shape}, {time.perf_counter() - start:.1f} s, error vs FD {errors}")

# %%
# check, in both packages: the reparameterized primal is the naive one bit for bit, the naive derivative
# is exactly 0 (a rigid translation changes no sample's radiance), and reparam agrees with finite
# differences at every pixel within t standard errors (16 batches: 15 degrees of freedom; two-sided,
# family-wise 1e-3 Šidák-corrected over the pixels) plus 1 % of the largest derivative, the resolution
# of finite differences with common random numbers
for name, (image, gradients) in results.items():
    naive, reparam, fd = gradients["naive"], gradients["reparam"], gradients["finite differences"]
    assert np.array_equal(reparam.value, naive.value) and np.array_equal(image.value, naive.value), name
    assert np.all(naive.derivative == 0.0), name
    quantile = stats.t.ppf(1 - sidak(1e-3, fd.derivative.size) / 2, fd.batches - 1)
    tolerance = quantile * np.hypot(reparam.derivative_stderr, fd.derivative_stderr)
    assert np.all(
        np.abs(reparam.derivative - fd.derivative) <= tolerance + 0.01 * np.abs(fd.derivative).max()
    ), name

# %% [markdown]
# One plotting helper draws both: a 1D film as strips and curves, a 2D film as images, each
# derivative on one diverging scale shared by the methods.

# %%
ptu.plot_gradient_panel(*results["flatland"], title=f"flatland silhouette: d/d {PARAM}")

# %% [markdown]
# The same call on the sphere's result: the derivative lives on the box's outline, positive on the
# side it moves away from (the sky, brighter than the box, takes its place) and negative on the
# side it moves into.

# %%
ptu.plot_gradient_panel(*results["sphere3d"], title=f"sphere3d silhouette: d/d {PARAM}")

# %% [markdown]
# ## 2. Rotations instead of translations
#
# In flatland the change of variables for directions is $\varphi \mapsto \varphi + \Delta$, a
# rotation of the circle. On $S^2$ it is a rotation matrix $R(\theta)$, the identity at $\theta_0$,
# chosen so that the direction $\omega_p(\theta)$ toward a point on the moving occluder moves
# exactly: $\dot R\,\omega_p = \dot\omega_p$. `sphere3d.rotation` builds it as the rotation taking
# $a = \operatorname{detach}(\omega_p)$ to $b = \omega_p$ (Sec. 4.1),
#
# $$
# R(a \to b) = c\,I + [v]_\times + \frac{v\,v^\top}{1 + c}, \qquad v = a \times b,\ c = a \cdot b ,
# $$
#
# which in value is the identity ($v = 0$, $c = 1$) and in derivative is the skew matrix
# $\dot R = [a \times \dot b]_\times$, an infinitesimal rotation. Samples are rotated as
# $R\cdot\operatorname{detach}(\omega)$: their values do not change, only their tangents. We build
# it for a point $p(\theta) = (0.3 + \theta, 0.2, 1)$ seen from the origin and apply it to that
# direction and to 1000 random ones.

# %%
theta = variable(0.0)
p = np.stack([0.3 + theta, 0.2 + 0.0 * theta, 1.0 + 0.0 * theta])
omega_p = p / np.sqrt(np.sum(p * p))  # a unit Dual: its tangent is dω_p/dθ
rotation = Rotation.following(omega_p[None, :])
followed = rotation.apply(detach(omega_p)[None, :])[0]
others = stream(SEED, "directions").standard_normal((1000, 3))
others /= np.linalg.norm(others, axis=1, keepdims=True)
rotated = rotation.apply(others)
R = rotation_matrix(detach(omega_p), omega_p)
R_dot = tangent(R)
print("dω_p/dθ        :", np.round(tangent(omega_p), 6))
print("tangent of R ω_p:", np.round(tangent(followed), 6))
print("R at θ0 (value):\n", np.round(detach(R), 12), "\ndR/dθ:\n", np.round(R_dot, 6))

# %%
# check: R follows the point exactly (1e-12), leaves every sample's value untouched (bit for bit), and its
# derivative is a skew-symmetric matrix (an infinitesimal rotation, 1e-12) whose action on any direction
# is the matrix product
assert np.allclose(tangent(followed), tangent(omega_p), rtol=0.0, atol=1e-12)
assert np.array_equal(detach(rotated), others)
assert np.allclose(R_dot, -R_dot.T, atol=1e-12) and np.allclose(detach(R), np.eye(3), atol=1e-12)
assert np.allclose(tangent(rotated), others @ R_dot.T, atol=1e-12)

# %% [markdown]
# ## 3. The von Mises–Fisher kernel
#
# The convolution kernel of Sec. 4.2 on $S^2$ is the von Mises–Fisher density
# $\frac{\kappa}{2\pi(1 - e^{-2\kappa})}\,e^{\kappa(\mu\cdot\omega - 1)}$. Its sampler inverts
# the distribution of $s = 1 - \mu\cdot\omega$, which is exponential with rate $\kappa$ truncated to
# $[0, 2]$: $E[s] = 1/\kappa - 2e^{-2\kappa}/(1 - e^{-2\kappa})$. On the circle the von Mises kernel
# $e^{\kappa\cos\varphi}/(2\pi I_0(\kappa))$ has $E[1 - \cos\varphi] = 1 - I_1(\kappa)/I_0(\kappa)$, about
# $1/(2\kappa)$: for large $\kappa$ both are Gaussians of variance $1/\kappa$ per tangent direction, one
# direction on $S^1$, two on $S^2$. We sample both at $\kappa = 1000$, the library's default for
# shading.

# %%
kappa, n = 1000.0, 200_000
mu = np.array([0.0, 0.0, 1.0])
s_sphere = 1.0 - sample_vmf(stream(SEED, "vmf").random((n, 2)), mu, kappa) @ mu
s_circle = 1.0 - np.cos(sample_von_mises(stream(SEED, "von mises").random(n), 0.0, kappa))
expected = {
    "S² (vMF)": 1.0 / kappa - 2.0 * np.exp(-2.0 * kappa) / -np.expm1(-2.0 * kappa),
    "S¹ (von Mises)": 1.0 - special.i1e(kappa) / special.i0e(kappa),  # 1 - I1(κ)/I0(κ), scaled Bessels
}
measured = {"S² (vMF)": s_sphere, "S¹ (von Mises)": s_circle}
for name, s in measured.items():
    print(f"{name:>15}: E[1 - cos] = {s.mean():.6e} ± {s.std(ddof=1) / np.sqrt(n):.1e}", end=", ")
    print(f"closed form {expected[name]:.6e}")

# %%
# check: both means match their closed forms within z standard errors (two-sided, family-wise 1e-3
# Šidák-corrected over the 2 kernels), and the sphere's is twice the circle's within 1 % (2 tangent axes
# against 1, each of variance 1/κ)
z2 = normal_quantile(1 - sidak(1e-3, 2))
for name, s in measured.items():
    assert abs(s.mean() - expected[name]) <= z2 * s.std(ddof=1) / np.sqrt(n), name
assert abs(expected["S² (vMF)"] / expected["S¹ (von Mises)"] - 2.0) < 0.02

# %% [markdown]
# The samples of $\kappa\,s$ on the sphere against the density they should follow, $e^{-x}$ (the
# truncation at $x = 2\kappa$ is invisible at this $\kappa$):

# %%
grid = np.linspace(0.0, 8.0, 401)
pt.plot_histogram(
    kappa * s_sphere, grid, np.exp(-grid), range=(0.0, 8.0), label="κ (1 − μ·ω), vMF samples",
    density_label="e^(−x)", xlabel="κ (1 − μ·ω)", title="vMF sampling at κ = 1000",
)  # fmt: skip

# %% [markdown]
# ## 4. Embree, and re-attaching its hits to θ
#
# The renderer traces *detached* rays (plain float32 numbers) with Embree, which reports which
# triangle each ray hits and where (barycentric coordinates), and then recomputes what it needs
# in float64 `Dual` arithmetic on the θ-dependent vertices (`docs/theory/architecture.md`).
# A point that *follows the shape*, the kind the probe heuristic needs, keeps the hit's
# barycentrics fixed on moving vertices (`attached_points`): for a translation its tangent is the
# translation direction.
#
# We trace one ray through every pixel centre of the 24 × 24 sphere `silhouette` camera with
# Embree and with the library's brute-force numpy tracer (every ray against every triangle), and
# re-attach the hits on the occluder to the scene bound with a `Dual` θ.

# %%
state = build_state(s3.load_scene(sphere_scene))  # the scene at θ0: triangles, camera, Embree tracer
cam = state.camera
cols, rows = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
directions = cam.directions(cols.ravel(), rows.ravel())
origin = detach(cam.origin)
start = time.perf_counter()
embree_hits = state.tracer.intersect(origin, directions)
embree_seconds = time.perf_counter() - start
brute = BruteForceTracer(detach(state.triangles), state.shape_of)
start = time.perf_counter()
brute_hits = brute.intersect(origin, directions)
brute_seconds = time.perf_counter() - start
moving = build_state(s3.load_scene(sphere_scene), PARAM, variable(0.0))  # the same scene, triangles as Duals
on_occluder = np.flatnonzero(embree_hits.shape == 0)
tri = moving.triangles[embree_hits.triangle[on_occluder]]
points = attached_points(tri, embree_hits.u[on_occluder], embree_hits.v[on_occluder])
hit = embree_hits.hit
print(f"{directions.shape[0]} rays, {hit.sum()} hits", end="; ")
print(f"Embree {embree_seconds * 1e3:.1f} ms, brute force {brute_seconds * 1e3:.1f} ms")
print(f"largest distance difference {np.max(np.abs(embree_hits.t[hit] - brute_hits.t[hit])):.2e}")
print("tangent of the first attached points:\n", np.round(tangent(points)[:3], 12))

# %%
# check: both tracers see the same shape along every ray and the same distance to float32 precision
# (1e-5 relative); the attached points lie on the rays (their values are the hits, 1e-5) and move
# exactly with the occluder, tangent (1, 0, 0)
assert np.array_equal(embree_hits.shape, brute_hits.shape)
assert np.allclose(embree_hits.t[hit], brute_hits.t[hit], rtol=1e-5, atol=0.0)
assert np.allclose(
    detach(points), origin + embree_hits.t[on_occluder, None] * directions[on_occluder], atol=1e-5
)
assert np.allclose(tangent(points), [1.0, 0.0, 0.0], rtol=0.0, atol=1e-12)

# %% [markdown]
# ## 5. The kernel's trade-off on the sphere, against a closed form
#
# A black triangle above a point, under a uniform sky of radiance 1: the irradiance at the point
# (normal $+z$) is $E = \pi - \Phi$, where $\Phi$ is the cosine-weighted solid angle of the triangle,
# given by Lambert's formula: with $u_i$ the unit vectors to the vertices,
#
# $$
# \Phi = \frac12 \Bigl|\sum_i \gamma_i\, n\cdot g_i\Bigr| ,
# \qquad g_i = \frac{u_i \times u_{i+1}}{\lVert u_i \times u_{i+1} \rVert} ,
# $$
#
# $\gamma_i$ the angle between $u_i$ and $u_{i+1}$. Written with `Dual`s, with the triangle translated by
# $\theta$ along $x$, its tangent is the exact $dE/d\theta$. The scene is a `mesh` shape with inline
# vertices; the camera is required by the scene format but unused by `irradiance`.
#
# The cosine-sampled integral is reparameterized inside a vMF kernel (`kappa`, default 1000);
# `kappa=None` uses one rotation for the whole hemisphere, probes drawn from the cosine lobe,
# which cannot follow all three edges of the triangle. As in tutorial 7 a wide kernel leaves bias
# and a narrow one adds variance. Each run uses $2^{17}$ samples.

# %%
vertices = np.array([[0.2, -0.3, 0.8], [0.9, -0.2, 0.8], [0.5, 0.4, 1.0]])
triangle_scene = {
    "name": "triangle_under_sky",
    "camera": {"position": [0.0, -3.0, 1.0], "look_at": [0.0, 0.0, 0.5], "fov": 0.8, "width": 8, "height": 8},
    "sky": 1.0,
    "shapes": [
        {"name": "tri", "type": "mesh", "vertices": vertices.tolist(), "faces": [[0, 1, 2]], "albedo": 0.0}
    ],
}


def lambert_irradiance(theta):
    """E = π - Φ at the origin, normal +z, with the triangle moved by theta along x (float or Dual)."""
    v = vertices + theta * np.array([1.0, 0.0, 0.0])
    u = v / np.sqrt(np.sum(v * v, axis=1))[:, None]
    total = 0.0
    for i in range(3):  # the triangle's three edges
        a, b = u[i], u[(i + 1) % 3]
        g = np.cross(a, b)
        total = total + np.arccos(np.sum(a * b)) * g[2] / np.sqrt(np.sum(g * g))
    return np.pi - 0.5 * np.abs(total)


E = lambert_irradiance(variable(0.0))
kernels = {"naive": None, "κ = None (no kernel)": None, "κ = 100": 100.0, "κ = 1000": 1000.0, "κ = 10⁴": 1e4}
estimates = {}
for label, k in kernels.items():
    method, options = ("naive", {}) if label == "naive" else ("reparam", {"kappa": k})
    estimates[label] = s3.irradiance(
        triangle_scene,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        "tri.translate.x",
        method,
        n=2**17,
        seed=SEED,
        **options,
    )
print(f"closed form: E = {detach(E):.5f}, dE/dθ = {tangent(E):.5f}")
for label, e in estimates.items():
    std = e.derivative_stderr * np.sqrt(e.n)
    print(f"{label:>22}: E = {e.value:.5f} ± {e.value_stderr:.5f}", end=", ")
    print(f"dE/dθ = {e.derivative:+.4f} ± {e.derivative_stderr:.4f}, std per sample {std:5.1f}")

# %%
# check (t quantile: 16 batches, 15 degrees of freedom, two-sided, family-wise 1e-3 Šidák-corrected over the
# 3 comparisons with the closed form): the value matches; naive returns 0; with the default κ = 1000 the
# derivative matches; without a kernel it is more than 5 standard errors off; and the standard deviation
# per sample grows from κ = 1000 to 10⁴ (measured × 1.8)
t3 = stats.t.ppf(1 - sidak(1e-3, 3) / 2, 15)
default = estimates["κ = 1000"]
assert abs(default.value - detach(E)) <= t3 * default.value_stderr
assert estimates["naive"].derivative == 0.0
assert abs(default.derivative - tangent(E)) <= t3 * default.derivative_stderr
no_kernel = estimates["κ = None (no kernel)"]
assert abs(no_kernel.derivative - tangent(E)) > 5 * no_kernel.derivative_stderr
assert estimates["κ = 10⁴"].derivative_stderr > 1.3 * default.derivative_stderr

# %% [markdown]
# The estimates with their 99 % intervals against the closed form:

# %%
pt.plot_estimates(
    estimates, float(tangent(E)), title="black triangle under the sky: dE/dθ on S²", ylabel="dE/dθ"
)

# %% [markdown]
# ## Summary
#
# The two packages share their API, their result types, their statistics and their plotting, so
# the same function differentiates a flatland film and a sphere image. What changes is geometry:
# a translation of the angle becomes a rotation that is the identity in value and a skew matrix
# in derivative; the von Mises kernel becomes the vMF kernel, with twice the mean $1 - \cos$ (two
# tangent directions); numpy ray casting becomes Embree, whose detached hits are re-attached to
# θ in float64 `Dual` arithmetic. The kernel's trade-off carries over unchanged: without a kernel
# one rotation cannot follow every edge of a triangle, and a very narrow kernel is noisy.
