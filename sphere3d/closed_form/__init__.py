r"""Closed forms the gradient methods are checked against, per pixel and per shading point.

Two scenes of one black triangle (albedo 0, emission 0) in front of a constant sky
``L`` have exact answers, values and θ-derivatives, to rounding:

1. **The camera image** (:func:`triangle_image`). A camera ray either escapes to the
   sky (radiance L) or meets the triangle (radiance 0), so the pixel integral of
   :mod:`sphere3d.integrator` is

       $I(p) = ∫ k(s) L(\mathrm{ray}(c_p + s)) ds = L (1 - ∫_T k(x - c_p) dx)$,

   with k the pixel filter of :mod:`sphere3d.sampling`, $c_p$ the pixel centre and T the
   triangle projected to the film (pixel coordinates). The film integral is reduced to
   the triangle's three edges by Green's theorem and the edge integrals are computed by
   Gauss–Legendre quadrature between the kinks of the filter (:func:`polygon_filter_integral`);
   its derivative is the Reynolds transport of T's boundary (:func:`polygon_filter_derivative`),
   the silhouette term of Loubet et al. 2019, Sec. 3.2, that a gradient method must
   recover at moving visibility edges.
2. **The irradiance at a point under the sky** (:func:`occluded_sky_irradiance`):
   $E = π L - L Φ(T)$, Φ the projected solid angle of the triangle by Lambert's
   polygon formula (:func:`projected_solid_angle`), Dual-aware, so its derivative comes
   with it; :func:`polygon_irradiance` gives a uniform polygonal emitter's $E = L Φ$. Under a square
   light instead of the sky (:func:`light_triangle_scene`), the light minus the triangle's shadow on
   its plane (:func:`occluded_light_irradiance`): the emitter strategy's integral.

A black convex mesh (:func:`icosphere_scene`) has the camera image of its front faces
(:func:`convex_image`): a silhouette of many edges whose images move differently when it turns.

A third scene adds a static black triangle behind the moving one (:func:`junction_scene`): its
camera image (:func:`junction_image`) is the filter integrated over the union of the two, whose
derivative carries the two T-junctions where the moving edges cross the static one
(:mod:`sphere3d.reparam.junctions`), by clipping on Duals (:func:`clip_convex`); moved until a vertex
of the moving triangle lies just under the static edge (:func:`corner_junction_scene`), the two
junctions meet at a corner of the silhouette.

All are written from the scene's definition (camera frame, pixel mapping, filter
profiles, shape transform), not from the estimators' code. The scenes the tests and
``benchmarks/bench_reparam_bias.py`` use are built by :func:`pinhole_triangle_scene` and
:func:`sky_triangle_scene`; :func:`share_lost` measures the share of an exact derivative an
estimator misses.
"""

from sphere3d.closed_form.convex import convex_image, mesh_vertices
from sphere3d.closed_form.film import (
    QUADRATURE_NODES,
    TriangleImage,
    filter_cdf_1d,
    filter_kinks,
    filter_profile_1d,
    polygon_filter_derivative,
    polygon_filter_integral,
    project,
    triangle_image,
    triangle_vertices,
)
from sphere3d.closed_form.junction import clip_convex, junction_image
from sphere3d.closed_form.lambert import (
    Flux,
    boundary_flux,
    occluded_light_irradiance,
    occluded_sky_irradiance,
    polygon_irradiance,
    projected_solid_angle,
)
from sphere3d.closed_form.scenes import (
    PIXEL,
    TRIANGLE_SHAPE,
    ShareLost,
    corner_junction_scene,
    icosphere_scene,
    junction_scene,
    light_triangle_scene,
    pinhole_triangle_scene,
    share_lost,
    sky_triangle_scene,
    sliver_scene,
)

__all__ = [
    "PIXEL",
    "QUADRATURE_NODES",
    "TRIANGLE_SHAPE",
    "Flux",
    "ShareLost",
    "TriangleImage",
    "boundary_flux",
    "clip_convex",
    "convex_image",
    "corner_junction_scene",
    "filter_cdf_1d",
    "filter_kinks",
    "filter_profile_1d",
    "icosphere_scene",
    "junction_image",
    "junction_scene",
    "light_triangle_scene",
    "mesh_vertices",
    "occluded_light_irradiance",
    "occluded_sky_irradiance",
    "pinhole_triangle_scene",
    "polygon_filter_derivative",
    "polygon_filter_integral",
    "polygon_irradiance",
    "project",
    "projected_solid_angle",
    "share_lost",
    "sky_triangle_scene",
    "sliver_scene",
    "triangle_image",
    "triangle_vertices",
]
