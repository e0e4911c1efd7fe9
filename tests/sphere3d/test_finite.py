"""Every public function stays finite at the edges of what validation accepts, or refuses with one error.

Small renders (4 × 4 pixels, 2 samples) of every built-in scene under each method with
its options at the limits the validators let through: κ at both ends of (0, KAPPA_MAX],
no kernel, one probe, spread 0 and huge, paired (refused on the scenes with glossy shapes, one
error); finite-difference steps from 1e-12 to
just below 1 on a scale; irradiance with tiny and unnormalized normals. Then the
geometry that validation accepts in local coordinates but that collapses or overflows
in world space, refused by :func:`sphere3d.world.check_world`.
"""

from __future__ import annotations

import numpy as np
import pytest

import sphere3d as s3
from flatland.core.validate import ValidationError
from sphere3d.methods.reparam import KAPPA_MAX
from sphere3d.reparam.film_kernel import KAPPA_FILM_MAX
from sphere3d.world import COORD_MAX
from tests.tiers import sweep

OPTIONS = [
    ("naive", {}),
    ("finite_difference", {"h": 1e-12}),
    ("finite_difference", {"h": 0.999}),
    ("reparam", {"kappa": 1e-300}),
    ("reparam", {"kappa": KAPPA_MAX}),
    ("reparam", {"kappa": None, "probes": 1}),
    ("reparam", {"probes": 1, "spread": 0.0}),
    ("reparam", {"probes": 16, "spread": 1e300}),
    ("reparam", {"spread": 9.0}),
    ("reparam", {"kappa_film": 1e-300}),
    ("reparam", {"kappa_film": KAPPA_FILM_MAX, "probes": 16}),
    ("reparam", {"paired": True, "kappa": KAPPA_MAX, "probes": 1}),
    ("reparam", {"paired": True, "kappa": 1e-300, "spread": 1e300}),
]


def _small(name: str) -> dict:
    d = s3.load_scene(name).to_dict()
    d["camera"].update(width=4, height=4)
    return d


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(a)) for a in arrays)


@pytest.mark.parametrize("scene", sweep(s3.list_scenes(), ["silhouette"]))
def test01_renders_and_gradients_at_the_option_edges_are_finite(scene):
    d = _small(scene)
    image = s3.render(d, spp=2)
    assert _finite(image.value, image.stderr)
    # one parameter per kind: a scale (h < 1 only), a rotation of the first shape, the camera
    first = s3.load_scene(d).shapes[0].name
    glossy = any(shape.roughness is not None for shape in s3.load_scene(d).shapes)
    for param in (f"{first}.scale", f"{first}.rotate.z", "camera.translate.x"):
        for method, options in OPTIONS:
            if glossy and options.get("paired"):  # paired kernel samples on glossy shapes: refused
                with pytest.raises(ValidationError, match=r"paired.*glossy"):
                    s3.render_gradient(d, param, method=method, spp=2, **options)
                continue
            g = s3.render_gradient(d, param, method=method, spp=2, **options)
            assert _finite(g.value, g.value_stderr, g.derivative, g.derivative_stderr), (
                param,
                method,
                options,
            )
            e = s3.irradiance(
                d, [0.1, 0.2, 0.01], [0.0, 1e-300, 1e-300], param, method=method, n=8, **options
            )
            assert _finite(e.value, e.value_stderr, e.derivative, e.derivative_stderr), (
                param,
                method,
                options,
            )


def _with_tiny(scale: float, x: float) -> dict:
    d = _small("shadow")
    # first in the list, so that triangle 0 (read for probe misses) is the tiny one
    d["shapes"].insert(0, {"name": "tiny", "type": "rectangle", "scale": scale, "translate": [x, 0.0, 0.0]})
    return d


def test02_a_triangle_collapsed_in_world_space_is_refused_naming_the_shape():
    # 1e-13 at x = 600, where doubles are 1.1e-13 apart: the corners x = 600 ± 5e-14 round to 600 and the
    # rectangle has zero area; its normal was 0/0 (a RuntimeWarning, NaN) inside reparam
    with pytest.raises(
        ValidationError, match=r"shapes\[0\]: triangle 0 of 'tiny' has zero area in world space"
    ):
        s3.render_gradient(_with_tiny(1e-13, 600.0), "occluder.translate.x", spp=2)
    with pytest.raises(ValidationError, match=r"at scale 1e-13 and translate \[600.0, 0.0, 0.0\]"):
        s3.irradiance(
            _with_tiny(1e-13, 600.0), [0, 0, 0.01], [0, 0, 1], "occluder.translate.x", method="reparam"
        )
    with pytest.raises(ValidationError, match=r"shapes\[0\]: triangle 0 of 'tiny' has zero area"):
        s3.render(
            _with_tiny(1e-160, 0.0), spp=2
        )  # |e1 × e2|² ~ 1e-640 underflows to 0 (from edges below ~1e-77)
    # the same shape near the origin, or 4e-13 at x = 600 (corners 3.5 ulps apart), is a valid triangle
    for scale, x in ((1e-13, 1.0), (4e-13, 600.0), (1e-70, 0.0)):
        g = s3.render_gradient(_with_tiny(scale, x), "tiny.translate.x", spp=2)
        assert _finite(g.value, g.derivative, g.derivative_stderr)
    # a scale step that collapses the shape only at θ = -h names the parameter and the offset
    with pytest.raises(
        ValidationError, match=r"'tiny' has zero area in world space \(with tiny.scale offset by"
    ):
        s3.render_gradient(_with_tiny(1e-12, 600.0), "tiny.scale", method="finite_difference", spp=2, h=0.9)


def test03_coordinates_beyond_float32_tracing_and_kernels_beyond_float64_are_refused():
    d = _small("shadow")
    d["shapes"][0]["scale"] = 1e18  # the 6 × 6 floor reaches 3e18
    with pytest.raises(
        ValidationError, match=r"shapes\[0\]: 'floor' reaches \|coordinate\| 3e\+18 in world space"
    ):
        s3.render(d, spp=2)
    d["shapes"][0]["scale"] = COORD_MAX / 3.0  # just inside: renders
    assert _finite(s3.render(d, spp=2).value)
    with pytest.raises(
        ValidationError, match=r"camera.position: is \[1e\+300, -4.0, 3.0\] in world space \(with"
    ):
        s3.render_gradient(_small("shadow"), "camera.translate.x", method="finite_difference", spp=2, h=1e300)
    with pytest.raises(ValidationError, match=r"point: must lie within ±1e\+18"):
        s3.irradiance("shadow", [1e300, 0, 0], [0, 0, 1])
    with pytest.raises(ValidationError, match=r"kappa: must be <= 1e\+15 .*, got 1e\+16"):
        s3.render_gradient(_small("shadow"), "occluder.translate.x", spp=2, kappa=1e16)


@pytest.mark.parametrize("h", [1.0, 1.5])
def test04_finite_differences_refuse_a_scale_step_of_one_or_more(h):
    # the scale 1 + θ at θ = -h would be <= 0 (a mirrored or collapsed shape): refused for images and points
    message = rf"h: must be < 1 for a scale parameter \(the scale 1 - h must stay > 0\), got {h!r}"
    with pytest.raises(ValidationError, match=message):
        s3.render_gradient(_small("shadow"), "occluder.scale", method="finite_difference", spp=2, h=h)
    with pytest.raises(ValidationError, match=message):
        s3.irradiance("shadow", [0, 0, 0.01], [0, 0, 1], "occluder.scale", method="finite_difference", h=h)
    g = s3.render_gradient(_small("shadow"), "occluder.translate.x", method="finite_difference", spp=2, h=h)
    assert _finite(g.derivative)  # only a scale is bounded
