"""The optimiser in sphere3d: the loss gradient from sphere3d's renders, recoveries, silhouettes, bad inputs.

The optimiser itself (Adam, the loss, the history) is :mod:`flatland.core.optimize`'s, tested in
tests/flatland/test_optimize.py; here sphere3d's renderer is injected (:func:`sphere3d.optimize`).

1. The loss gradient $2 Σ r D$ from sphere3d's images is the derivative of the loss: with one seed for
   every render (common random numbers) and a parameter that moves no discontinuity (the occluder's
   albedo: naive's derivative is the estimator's exact derivative, and the image is affine in it),
   the central difference of the rendered loss agrees to rounding (1e-9 relative at h = 1e-3: the
   loss is a quadratic in the albedo, its central difference exact but for rounding).
2. Pose and albedo from one image (``hard_shadow_cube`` on a 32 x 32 film, reparam at 16 spp, 100
   steps): the box occluder's translation x, y, z (range [-0.2, 0.2] each), its rotation about z
   ([-0.5, 0.5] rad) and its albedo (its range [0, 1]) each within 1 % of its range of the target's
   offsets (measured errors, seeds 0 and 1: translations at most 0.0014, the rotation 0.0035 rad, the
   albedo 0.0008).
   A sphere's rotation would be invisible (its image does not change): the box's is not.
   Slow: tutorial 12 (tests/test_tutorials.py, in ``make test``) runs the same recovery (the same
   scene, film, parameters, truth, ranges, learning rates, spp and steps; its own seed) and asserts
   the same 1 % goal.
3. Shape from 4 views (slow): nine coefficients (degree <= 2) of a black icosphere before the sky,
   cameras around it at four azimuths and elevations: every view's silhouette
   (:func:`~sphere3d.optimize.silhouette`) has an IoU >= 0.97 with the target's, from initial IoUs
   below 0.97 (measured: initial 0.77-0.81, final 0.976-0.985, seed 0).
4. Silhouettes: a scene's offsets move its silhouette as the edited scene's, bit for bit; the IoU is 1
   for equal masks, 0 for disjoint ones, and |A ∩ B| / |A ∪ B| otherwise.
5. Reproducible: the same seed gives the same history bit for bit; the history has the documented
   shapes (images of (views, height, width)).
6. Bad input: one ValidationError naming the field.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("embreex")

import sphere3d as s3
from flatland.core.optimize import l2_gradient, l2_loss
from flatland.core.validate import ValidationError
from sphere3d.optimize import optimize, render_targets, silhouette, silhouette_iou
from sphere3d.scene import load_scene
from sphere3d.state import moved_scene
from tests.tiers import SLOW


def small(name: str, size: int) -> s3.scene.Scene:
    d = load_scene(name).to_dict()
    d["camera"].update(width=size, height=size)
    return load_scene(d)


def test01_the_loss_gradient_is_the_derivative_of_the_rendered_loss():
    scene, param, h = small("hard_shadow", 12), "occluder.albedo", 1e-3
    target = s3.render(moved_scene(scene, param, 0.2), spp=8, seed=11).value

    def loss(theta):
        image = s3.render_gradient(moved_scene(scene, param, theta), [param], method="naive", spp=4, seed=3)
        return l2_loss(image.value, target), l2_gradient(image.value - target, image.derivative)[0]

    value, gradient = loss(0.0)
    central = (loss(h)[0] - loss(-h)[0]) / (2 * h)
    assert value > 0.0 and abs(gradient) > 1.0
    assert abs(gradient - central) <= 1e-9 * abs(gradient)


@SLOW
def test02_pose_and_albedo_from_one_image():
    scene = small("hard_shadow_cube", 32)
    params = [
        "occluder.translate.x",
        "occluder.translate.y",
        "occluder.translate.z",
        "occluder.rotate.z",
        "occluder.albedo",
    ]
    ranges = np.array([0.4, 0.4, 0.4, 1.0, 1.0])
    truth = np.array([0.08, -0.06, 0.05, 0.3, -0.15])
    targets = render_targets(scene, params, truth, spp=256, seed=1)
    result = optimize(
        scene, params, targets, method="reparam", steps=100, lr=[0.02, 0.02, 0.02, 0.05, 0.02], spp=16, seed=0
    )
    assert result.steps == 100 and result.loss[-1] < 0.1 * result.loss[0]
    errors = np.abs(result.theta[-1] - truth)
    assert np.all(errors <= 0.01 * ranges), dict(zip(params, errors, strict=True))


def _views(size: int) -> list[dict]:
    views = []
    for azimuth, elevation in [(0.0, 0.3), (math.pi / 2, 0.3), (math.pi / 4, -0.4), (3 * math.pi / 4, 1.2)]:
        position = [
            3 * math.cos(elevation) * math.sin(azimuth),
            -3 * math.cos(elevation) * math.cos(azimuth),
            3 * math.sin(elevation),
        ]
        views.append({"position": position, "look_at": [0, 0, 0], "fov": 0.5, "width": size, "height": size})
    return views


@SLOW
def test03_shape_coefficients_from_four_views():
    size = 24
    scene = load_scene(
        {
            "name": "blob",
            "sky": 1.0,
            "camera": _views(size)[0],
            "shapes": [
                {"name": "blob", "type": "icosphere", "radius": 0.5, "subdivisions": 3, "albedo": 0.0}
            ],
        }
    )
    params = [f"blob.shape.{k}" for k in range(9)]
    truth = 0.5 * np.array([0.05, 0.1, -0.08, 0.12, 0.1, -0.06, 0.15, 0.08, -0.1])
    views = _views(size)
    targets = render_targets(scene, params, truth, views=views, spp=256, seed=1)
    cameras = [load_scene({**scene.to_dict(), "camera": v}).camera for v in views]
    target_scene = moved_scene(scene, params, truth)

    def ious(theta):
        moved = moved_scene(scene, params, theta)
        return [
            silhouette_iou(silhouette(target_scene, "blob", c), silhouette(moved, "blob", c)) for c in cameras
        ]

    assert max(ious(np.zeros(9))) < 0.97
    result = optimize(
        scene, params, targets, views=views, method="reparam", steps=100, lr=0.02, spp=8, seed=0
    )
    assert min(ious(result.theta[-1])) >= 0.97


def test04_silhouettes_follow_the_offsets_and_the_iou_is_the_ratio():
    scene = small("hard_shadow", 24)
    moved = moved_scene(scene, ["occluder.translate.x", "occluder.scale"], [0.1, 0.2])
    d = scene.to_dict()
    d["shapes"][2]["translate"][0] += 0.1
    d["shapes"][2]["scale"] *= 1.2
    edited = silhouette(load_scene(d), "occluder")
    here = silhouette(moved, "occluder")
    assert here.any() and not here.all() and np.array_equal(here, edited)
    base = silhouette(scene, "occluder")
    assert silhouette_iou(base, base) == 1.0 and silhouette_iou(base, ~base) == 0.0
    expected = np.count_nonzero(base & here) / np.count_nonzero(base | here)
    assert silhouette_iou(base, here) == expected and 0.0 < expected < 1.0


def test05_same_seed_same_history_with_documented_shapes():
    scene = small("hard_shadow", 8)
    params = ["occluder.translate.x", "occluder.albedo"]
    targets = render_targets(scene, params, [0.05, 0.1], spp=16)
    runs = [optimize(scene, params, targets, steps=3, spp=2, seed=4, record=[0, 2, 3]) for _ in range(2)]
    for name in ("theta", "loss", "gradient", "targets"):
        assert np.array_equal(getattr(runs[0], name), getattr(runs[1], name)), name
    result = runs[0]
    assert result.theta.shape == (4, 2) and result.loss.shape == (4,) and result.gradient.shape == (3, 2)
    assert sorted(result.images) == [0, 2, 3] and result.images[3].shape == (1, 8, 8) == result.targets.shape
    assert not result.theta.flags.writeable


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"params": "occluder.nope"}, "params"),
        ({"params": []}, "params"),
        ({"targets": np.zeros((8, 9))}, r"targets\[0\]"),
        ({"targets": [np.zeros((8, 8))] * 2}, "targets"),
        ({"targets": np.full((8, 8), np.nan)}, r"targets\[0\]"),
        ({"views": []}, "views"),
        ({"views": [{"position": [0, 0, 0]}]}, r"views\[0\]"),
        ({"steps": 0}, "steps"),
        ({"lr": -1.0}, "lr"),
        ({"bounds": {"occluder.albedo": (-0.9, 0.1)}}, r"bounds\['occluder.albedo'\]"),
        ({"method": "magic"}, "method"),
    ],
)
def test06_bad_input_is_one_error_naming_the_field(kwargs, field):
    scene = small("hard_shadow", 8)
    call = {"params": ["occluder.albedo"], "targets": np.zeros((8, 8)), "steps": 1, "spp": 1, **kwargs}
    with pytest.raises(ValidationError, match=f"^{field}"):
        optimize(scene, **call)
