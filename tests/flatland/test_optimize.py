"""The optimiser: Adam, the loss and its gradient, recoveries in flatland, and bad inputs.

1. Adam's iterates are exact: on a linear loss (constant gradient g) the bias-corrected moments are
   g and g², so $θ_t = θ_0 - η t g / (|g| + ε)$ to rounding; on a quadratic they equal a scalar
   transcription of Kingma and Ba's Algorithm 1 to rounding; the projection clips to the bounds.
2. The loss gradient $2 Σ r D$ (:func:`~flatland.core.optimize.l2_gradient`) is the derivative of the
   loss: with one seed for every render (common random numbers) and a parameter that moves no
   discontinuity (an albedo: the naive derivative is the estimator's exact derivative), the central
   difference of the rendered loss agrees to its truncation error $O(h^2)$ (bound 1e-6 relative at
   h = 1e-4: the loss is a quadratic in the albedo, so the truncation error is rounding).
3. Pose and albedo from one image: the occluder's x and y translation and its albedo in ``shadow``,
   each within 1 % of its range ([-0.5, 0.5], [-0.4, 0.4], the albedo's [0, 1]) in 100 steps
   (measured over seeds 0-5 at 64 spp: errors at most 0.0044, 0.0030, 0.0039).
4. Naive stalls where visibility is all that moves: on a translation only, its loss shows no trend.
   The run's losses are noisy estimates of L(θ) at an essentially fixed θ; the mean of the last 20
   minus the mean of the first 20 is compared with $z σ \\sqrt{2/20}$, σ the losses' standard
   deviation and z = 3.29 (two-sided 0.1 %), while reparam's loss on the same problem falls by more
   than 10× and its θ reaches the target.
5. Shape from 4 views: five Fourier coefficients of a 24-gon before the sky, from cameras at 0, 45,
   90 and 135 degrees: every view's silhouette (the polygon's covered film interval,
   :func:`~flatland.optimize.film_interval`) has an IoU >= 0.97 with the target's, from initial IoUs
   below 0.97 (measured IoUs 0.997-0.999, seeds 0-1).
6. Reproducible: the same seed gives the same history bit for bit; every render of a run has its own
   seed. The history has the documented shapes and is read-only.
7. Bad input: one ValidationError naming the field.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatland.core.adam import EPS, AdamState, adam_step
from flatland.core.optimize import l2_gradient, l2_loss, step_seeds
from flatland.core.validate import ValidationError
from flatland.optimize import film_interval, optimize, render_targets, silhouette_iou
from flatland.render import render, render_gradient
from flatland.scene import load_scene
from flatland.state import moved_scene

POSE = ["occluder.translate.x", "occluder.translate.y", "occluder.albedo"]
POSE_TRUTH = np.array([0.15, -0.1, 0.3])
POSE_RANGE = np.array([1.0, 0.8, 1.0])  # of x in [-0.5, 0.5], y in [-0.4, 0.4], the albedo in [0, 1]


def test01_adam_iterates_are_exact():
    # linear loss: constant gradient, the first moment corrected to g, the second to g^2
    g = np.array([2.0, -0.5, 1e-3])
    state = AdamState.start(np.zeros(3))
    for _ in range(7):
        state = adam_step(state, g, 0.01)
    np.testing.assert_allclose(state.theta, -0.01 * 7 * g / (np.abs(g) + EPS), rtol=1e-14)
    # quadratic L = a (θ - c)^2 / 2 against Algorithm 1 written out in scalars
    a, c, lr, theta = 3.0, 0.7, 0.05, 0.0
    m = v = 0.0
    state = AdamState.start(np.array([0.0]))
    for t in range(1, 31):
        grad = a * (theta - c)
        m = 0.9 * m + 0.1 * grad
        v = 0.999 * v + 0.001 * grad * grad
        theta = theta - lr * (m / (1 - 0.9**t)) / (math.sqrt(v / (1 - 0.999**t)) + 1e-8)
        state = adam_step(state, a * (state.theta - c), lr)
        assert state.theta[0] == pytest.approx(theta, rel=1e-14, abs=1e-15)
    # the projection: a step past a bound stops at it
    clipped = adam_step(AdamState.start(np.array([0.0, 0.0])), np.array([1.0, -1.0]), 0.5, -0.2, 0.3)
    np.testing.assert_array_equal(clipped.theta, [-0.2, 0.3])


def test02_the_loss_gradient_is_the_derivative_of_the_loss():
    scene = load_scene("shadow").with_camera(pixels=16)
    param, h = "occluder.albedo", 1e-4
    target = render(moved_scene(scene, param, 0.2), spp=64, seed=11).value[None]

    def loss(theta: float) -> float:
        return l2_loss(render(moved_scene(scene, param, theta), spp=32, seed=3).value[None], target)

    g = render_gradient(scene, [param], method="naive", spp=32, seed=3)
    gradient = l2_gradient(g.value[None] - target, g.derivative[:, None])
    difference = (loss(h) - loss(-h)) / (2 * h)
    assert gradient.shape == (1,) and abs(gradient[0]) > 0.1
    assert gradient[0] == pytest.approx(difference, rel=1e-6)


def test03_pose_and_albedo_are_recovered_from_one_image():
    scene = load_scene("shadow")
    targets = render_targets(scene, POSE, POSE_TRUTH, spp=4096, seed=99)
    bounds = {POSE[0]: (-0.5, 0.5), POSE[1]: (-0.4, 0.4)}
    result = optimize(scene, POSE, targets, steps=100, lr=0.03, decay=0.05, spp=64, seed=0, bounds=bounds)
    assert result.steps <= 100
    error = np.abs(result.theta[-1] - POSE_TRUTH) / POSE_RANGE
    assert np.all(error <= 0.01), error
    assert result.loss[-1] < 0.1 * result.loss[0]


def _trend_z(loss: np.ndarray, n: int = 20) -> float:
    """(mean of the last n losses - mean of the first n) / (σ sqrt(2/n)), σ the losses' spread."""
    return float((loss[-n:].mean() - loss[:n].mean()) / (loss.std(ddof=1) * math.sqrt(2.0 / n)))


def test04_naive_stalls_on_a_translation_and_reparam_does_not():
    scene = load_scene("shadow")
    param, truth = ["occluder.translate.x"], np.array([0.15])
    targets = render_targets(scene, param, truth, spp=4096, seed=99)
    runs = {
        m: optimize(scene, param, targets, method=m, steps=60, lr=0.03, spp=32, seed=1)
        for m in ("naive", "reparam")
    }
    naive, reparam = runs["naive"], runs["reparam"]
    assert abs(_trend_z(naive.loss)) < 3.29
    assert abs(naive.theta[-1, 0]) < 0.01 * truth[0]  # it did not move a hundredth of the way
    assert reparam.loss[-1] < 0.1 * reparam.loss[0]
    assert abs(reparam.theta[-1, 0] - truth[0]) < 0.01


def _blob_scene() -> dict:
    n = 24
    pts = [[0.5 * math.cos(2 * math.pi * i / n), 0.5 * math.sin(2 * math.pi * i / n)] for i in range(n)]
    shape = {"name": "blob", "type": "polygon", "points": pts}
    return {"name": "blob", "camera": _camera(0), "sky": 1.0, "shapes": [shape]}


def _camera(degrees: float) -> dict:
    a = math.radians(degrees)
    position, direction = [2.5 * math.cos(a), 2.5 * math.sin(a)], [-math.cos(a), -math.sin(a)]
    return {"position": position, "direction": direction, "fov": 0.9, "pixels": 64, "filter": "tent"}


def test05_a_blob_shape_is_recovered_from_four_views():
    scene = load_scene(_blob_scene())
    views = [_camera(a) for a in (0, 45, 90, 135)]
    params = [f"blob.shape.{k}" for k in range(5)]
    truth = np.array([0.12, 0.15, -0.1, 0.2, 0.18])
    targets = render_targets(scene, params, truth, views=views, spp=1024, seed=99)
    result = optimize(scene, params, targets, steps=100, lr=0.03, decay=0.05, spp=16, seed=0, views=views)
    target_scene, found = moved_scene(scene, params, truth), moved_scene(scene, params, result.theta[-1])
    cameras = [load_scene({**_blob_scene(), "camera": v}).camera for v in views]
    before = [
        silhouette_iou(film_interval(target_scene, "blob", c), film_interval(scene, "blob", c))
        for c in cameras
    ]
    after = [
        silhouette_iou(film_interval(target_scene, "blob", c), film_interval(found, "blob", c))
        for c in cameras
    ]
    assert max(before) < 0.97 and min(after) >= 0.97, (before, after)
    assert silhouette_iou((0.0, 1.0), (0.5, 1.5)) == pytest.approx(1 / 3)  # the measure itself


def test06_a_run_is_reproducible_and_its_history_complete():
    scene = load_scene("shadow").with_camera(pixels=16)
    targets = render_targets(scene, POSE, POSE_TRUTH, spp=64)
    a, b = (optimize(scene, POSE, targets, steps=4, spp=8, seed=5, record=[0, 2, 4]) for _ in range(2))
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.loss, b.loss)
    assert a.theta.shape == (5, 3) and a.loss.shape == (5,) and a.gradient.shape == (4, 3)
    assert a.seconds.shape == (4,) and sorted(a.images) == [0, 2, 4] and a.images[4].shape == (1, 16)
    assert set(a.final) == set(POSE) and a.final[POSE[0]] == a.theta[-1, 0]
    with pytest.raises(ValueError, match="read-only"):
        a.theta[0, 0] = 1.0
    other = optimize(scene, POSE, targets, steps=4, spp=8, seed=6)
    assert not np.array_equal(other.loss, a.loss)
    seeds = step_seeds(5, 4, 2)
    assert seeds.shape == (5, 2, 2) and np.unique(seeds).size == seeds.size
    assert np.all(a.theta[:, 2] >= -0.5) and np.all(a.theta[:, 2] <= 0.5)  # the albedo's default bounds


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"params": ["occluder.nothing"]}, "params"),
        ({"params": []}, "params"),
        ({"targets": [np.zeros(15)]}, r"targets\[0\]"),
        ({"targets": [np.zeros(16), np.zeros(16)]}, "targets"),
        ({"targets": [np.full(16, np.nan)]}, r"targets\[0\]"),
        ({"views": []}, "views"),
        ({"views": [{"position": [0, 0]}]}, r"views\[0\]"),
        ({"steps": 0}, "steps"),
        ({"lr": 0.0}, "lr"),
        ({"lr": [0.1, 0.2, 0.3]}, "lr"),
        ({"method": "newton"}, "method"),
        ({"kappa": -1.0}, "kappa"),
        ({"decay": 0.0}, "decay"),
        ({"bounds": {"occluder.albedo": (-0.9, 0.1)}}, "bounds"),
        ({"bounds": {"light.emission": (-1, 1)}}, "bounds"),
        ({"record": [7]}, "record"),
    ],
)
def test07_bad_input_is_one_clear_error(change, field):
    scene = load_scene("shadow").with_camera(pixels=16)
    call = {"params": ["occluder.translate.x", "occluder.albedo"], "targets": [np.zeros(16)], "steps": 2}
    call.update(change)
    with pytest.raises(ValidationError, match=f"^{field}"):
        optimize(scene, call.pop("params"), call.pop("targets"), spp=4, **call)
