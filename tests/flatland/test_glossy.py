r"""Glossy shapes in flatland scenes: the ``roughness`` key, the lobe in the shading and along paths.

A shape with a ``roughness`` α reflects with the GGX BSDF of :mod:`flatland.bsdf` (albedo = F);
:func:`flatland.integrator.shade` samples it (visible normals) beside the emitters by the balance
heuristic, and a path goes on along that sample (:mod:`flatland.glossy`).

Tolerances: Monte Carlo estimates are compared as $|mean - reference| <= q · stderr$ with the
normal (or Student-t over batches) quantile q at ALPHA = 1e-3, Šidák-corrected over the
comparisons of a test, fixed seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland import glossy, integrator
from flatland.core.dual import detach
from flatland.core.rng import Draws
from flatland.core.validate import ValidationError
from flatland.lights import Lights
from flatland.scene import load_scene, parameter_names
from flatland.state import build_state, moved_scene

ALPHA = 1e-3


def _glossy_floor(roughness: float = 0.2, albedo: float = 0.9) -> dict:
    return {
        "name": "glossy_floor",
        "camera": {"position": [-2.5, 1.6], "direction": [2.7, -1.6], "fov": 1.0, "pixels": 8},
        "shapes": [
            {"name": "floor", "type": "segment", "points": [[-3, 0], [3, 0]], "albedo": albedo,
             "roughness": roughness},
            {"name": "occluder", "type": "segment", "points": [[-0.4, 0.8], [0.4, 0.8]], "albedo": 0.5},
            {"name": "light", "type": "segment", "points": [[-0.6, 2.0], [0.6, 2.0]], "emission": 4.0,
             "one_sided": True, "fade": 0.1},
        ],
        "parameters": ["occluder.translate.x", "floor.roughness"],
    }  # fmt: skip


@pytest.mark.parametrize(
    ("value", "why"),
    [(0.0, "perfect mirror"), (-0.1, "perfect mirror"), (1.5, "(0, 1]"), ("rough", "number"), (np.nan, "")],
    ids=["mirror", "negative", "above_one", "string", "nan"],
)
def test01_a_roughness_outside_zero_one_is_refused_naming_the_field_and_why(value, why):
    scene = _glossy_floor()
    scene["shapes"][0]["roughness"] = value
    with pytest.raises(ValidationError) as err:
        load_scene(scene)
    assert err.value.field == "shapes[0].roughness"
    assert why in str(err.value)
    if why == "perfect mirror":
        assert "no integral to reparameterize" in str(err.value)


def test02_roughness_is_a_parameter_of_glossy_shapes_only():
    scene = load_scene(_glossy_floor(0.25))
    assert scene.shape("floor").glossy and not scene.shape("occluder").glossy
    names = parameter_names(scene)
    assert "floor.roughness" in names and "occluder.roughness" not in names
    assert load_scene(scene.to_dict()) == scene  # the key round-trips; diffuse shapes write none
    assert "roughness" not in scene.to_dict()["shapes"][1]
    with pytest.raises(ValidationError, match="diffuse"):
        build_state(scene, "occluder.roughness", 0.0)
    state = build_state(scene, "floor.roughness", 0.05)
    assert np.allclose(detach(state.roughness), [0.3, 0.0, 0.0]) and state.glossy.tolist() == [
        True,
        False,
        False,
    ]
    for bad in (-0.25, 0.8):  # to 0 (a mirror) and above 1
        with pytest.raises(ValidationError, match="roughness"):
            moved_scene(scene, "floor.roughness", bad)


def test03_the_lobe_code_on_diffuse_rows_is_the_diffuse_shading_to_rounding():
    """Through the lobe's code (every row diffuse), E-hat times ρ/2 and the cosine sample's throughput
    ρ cos/cos0 come out as the diffuse code's, sample by sample; a scene without glossy shapes never
    builds a lobe, so its shading is the diffuse code itself."""
    scene = load_scene("shadow")
    state = build_state(scene, None, 0.0)
    ctx = integrator.Context(state, state, Lights.of(state), integrator.Identity(), 2)
    n = 4096
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.uniform(-2.5, 2.5, n), np.zeros(n)])
    normal = np.tile([0.0, 1.0], (n, 1))
    prim = np.zeros(n, dtype=np.int64)  # the floor
    draws = Draws.of(1, np.arange(n))
    u = draws.uniforms("samples", 3)
    arriving = np.tile([0.6, -0.8], (n, 1))
    assert glossy.lobe_at(state, prim, arriving) is None
    lobe = glossy.Lobe(
        np.zeros(n, dtype=bool), glossy.angle_of_vector(-arriving), np.ones(n), np.full(n, 0.8)
    )
    e, b = integrator.shade(ctx, x, normal, prim, u, draws, True)
    r, g = integrator.shade(ctx, x, normal, prim, u, draws, True, lobe)
    assert np.mean(e) > 0.1
    np.testing.assert_allclose(r, 0.5 * 0.8 * e, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(g.throughput, 0.8 * integrator.cosine_ratio(b.cosine), rtol=1e-12, atol=1e-15)
    assert np.array_equal(g.hit, b.hit) and np.array_equal(g.prim, b.prim)
