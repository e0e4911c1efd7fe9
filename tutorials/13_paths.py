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
# # 13. Paths and glossy reflections in flatland
#
# **What you will learn.**
#
# - what `max_depth` adds: light that has bounced, checked against a white furnace's series
# - a glossy floor (`roughness`): a moving occluder seen through its blurred reflection
# - what naive AD misses at the first and at the second bounce, and which method recovers it
#
# Until now every integrand was direct illumination: a camera ray meets a surface, which reflects
# the light arriving straight from the emitters. With `max_depth` $= d$ the renderer follows
# paths of up to $d$ vertices, $L_d = \sum_{i=0}^{d} \mathcal{T}^i L_e$ (`docs/theory/radiometry.md`),
# and a shape with a `roughness` $\alpha$ reflects with the GGX lobe of `docs/theory/bsdf.md`
# instead of the diffuse $\rho/2$. Every integral along a path has its own moving discontinuities:
# an occluder's edge seen from the floor, and from the wall the floor reflects. The first cell
# imports the library and fixes the seed.

# %%
# %matplotlib inline
import numpy as np

import flatland as fl
from flatland.core.stats import family_quantile
from flatland.plotting import tutorials as ptu

SEED = 13
BATCHES = 16

# %% [markdown]
# ## 1. Depth: a white furnace
#
# The built-in `furnace` is a closed room whose walls all emit $L_e = 1$ and reflect diffusely with
# albedo $\rho = 0.6$. Radiance $L$ arriving from every direction is reflected as $\rho L$, so after
# $d$ vertices every pixel sees $L_d = L_e (1 - \rho^{d+1}) / (1 - \rho)$, wherever the walls are.
# We render depths 1 to 4.

# %%
furnace = fl.load_scene("furnace")
depths = (1, 2, 3, 4)
images = {d: fl.render(furnace, spp=256, seed=SEED, batches=BATCHES, max_depth=d) for d in depths}
series = {d: (1.0 - 0.6 ** (d + 1)) / (1.0 - 0.6) for d in depths}
for d in depths:
    print(f"depth {d}: image mean {images[d].value.mean():.4f}, closed form {series[d]:.4f}")

# %%
# check: every pixel of every depth within its Student-t interval (15 dof, Šidák over 4 x 16 pixels)
q = family_quantile(len(depths) * furnace.camera.pixels, 0.999, dof=BATCHES - 1)
for d in depths:
    assert np.all(np.abs(images[d].value - series[d]) <= q * images[d].stderr), d

# %% [markdown]
# ## 2. A glossy floor
#
# `glossy_reflection` has a glossy floor (roughness 0.2) that ends at a diffuse wall, a light
# above, and an occluder near the wall. From the camera's top pixel to its bottom one: the wall
# with the occluder's shadow, then the floor, which shows the occluder's blurred reflection against
# the sky's and, nearest the camera, the light's highlight. Depth 2 adds what the floor reflects
# of the lit wall.

# %%
scene = fl.load_scene("glossy_reflection").with_camera(pixels=32)
PARAM = "occluder.translate.x"
direct = fl.render(scene, spp=512, seed=SEED, batches=BATCHES)
bounced = fl.render(scene, spp=512, seed=SEED, batches=BATCHES, max_depth=4)
fig = ptu.plot_film({"depth 1": direct, "depth 4": bounced}, ylabel="radiance", scene=scene, param=PARAM)
fig

# %%
# check: paths only add light: depth 4 >= depth 1 in every pixel, within 3.29 standard errors of both
assert np.all(bounced.value - direct.value >= -3.29 * np.hypot(bounced.stderr, direct.stderr))
assert bounced.value.mean() > direct.value.mean() + 3.29 * np.hypot(bounced.stderr, direct.stderr).mean()

# %% [markdown]
# ## 3. What naive AD misses
#
# Moving the occluder along its own line, `occluder.translate.x`, changes nothing that naive AD
# differentiates: each camera ray meets the same point, with the same radiance. Everything the
# parameter does happens through visibility: the shadow on the wall, the reflection in the floor.
# Finite differences (h = 0.05, the same random numbers at $\theta \pm h$) see it at every depth;
# boundary terms and reparam see it at every depth (section 4); naive sees nothing.

# %%
args = {"seed": SEED, "batches": BATCHES, "progress": False}
naive = {d: fl.render_gradient(scene, PARAM, "naive", spp=256, max_depth=d, **args) for d in (1, 2)}
fd = {
    d: fl.render_gradient(scene, PARAM, "finite_difference", spp=4096, h=0.05, max_depth=d, **args)
    for d in (1, 2)
}
boundary = fl.render_gradient(scene, PARAM, "boundary", spp=1024, **args)
fig = ptu.plot_film(
    {
        "naive": naive[2],
        "finite_difference": fd[1],
        "finite_difference, depth 2": fd[2],
        "boundary": boundary,
    },
    title=f"d/d {PARAM}",
)
fig

# %%
# check: naive is 0 everywhere; boundary = FD at depth 1 per pixel (|z| <= Šidák quantile over 32 pixels)
assert all(np.max(np.abs(naive[d].derivative)) < 1e-12 for d in (1, 2))
z = (boundary.derivative - fd[1].derivative) / np.maximum(
    np.hypot(boundary.derivative_stderr, fd[1].derivative_stderr), 1e-12
)
assert np.max(np.abs(z)) <= family_quantile(scene.camera.pixels, 0.999, dof=BATCHES - 1)

# %% [markdown]
# The floor pixels between the wall and the highlight hold the occluder's reflection. At depth 2
# their derivative grows: the floor now also reflects the lit wall, whose shadow moves with the
# occluder. That term lives in the integral at the *second* vertex, which naive AD drops like
# the first; we sum it over those pixels.

# %%
floor = slice(10, 20)
sums = {
    d: (fd[d].derivative[floor].sum(), np.sqrt((fd[d].derivative_stderr[floor] ** 2).sum())) for d in (1, 2)
}
for d, (s, se) in sums.items():
    print(f"depth {d}: finite differences over the reflection {s:.3f} ± {se:.3f}; naive 0")

# %%
# check: the second bounce adds to the reflection's derivative by more than 3.29 standard errors
(s1, e1), (s2, e2) = sums[1], sums[2]
assert s2 - s1 > 3.29 * np.hypot(e1, e2) and s1 > 3.29 * e1

# %% [markdown]
# ## 4. Which method recovers what
#
# - `finite_difference` takes any depth, at the price of noise that grows as $1/h$;
# - `boundary` adds the jump terms of every integral along the path: at the camera and at every
#   vertex, including the glossy floor's (its lobe evaluated at each jump direction). On a path,
#   the radiance on each side of a jump is itself estimated by a path of the remaining depth,
#   traced from the side ray, and the term is weighted by the path's throughput to the vertex;
# - `reparam` changes variables in every integral along the path, and the path goes on along the
#   warped sample, carrying its kernel weight; it is unbiased where its probe heuristic holds
#   (`docs/theory/bsdf.md` measures where it does not on this scene), and noisier with depth.
#
# We compare both at depth 2 with the finite differences of section 3.

# %%
paths = {
    "boundary": fl.render_gradient(scene, PARAM, "boundary", spp=1024, max_depth=2, **args),
    "reparam": fl.render_gradient(scene, PARAM, "reparam", spp=2048, max_depth=2, **args),
}
fig = ptu.plot_film({"finite_difference, depth 2": fd[2], **paths}, title=f"d/d {PARAM}, depth 2")
fig

# %%
# check: both agree with finite differences at depth 2 per pixel (Šidák over 2 x 32 pixels)
q = family_quantile(2 * scene.camera.pixels, 0.999, dof=BATCHES - 1)
for name, g in paths.items():
    z = (g.derivative - fd[2].derivative) / np.maximum(
        np.hypot(g.derivative_stderr, fd[2].derivative_stderr), 1e-12
    )
    assert np.max(np.abs(z)) <= q, name
