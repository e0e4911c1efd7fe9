"""sphere3d figures from real (tiny) renders: written, of a sensible size, not blank, diverging."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

pytest.importorskip("embreex")

from sphere3d import plot
from sphere3d.render import render, render_gradient
from sphere3d.scene import load_scene


@pytest.fixture(scope="module")
def small():
    data = load_scene("shadow").to_dict()
    data["camera"].update(width=24, height=18)
    scene = load_scene(data)
    primal = render(scene, spp=4, seed=0)
    gradients = {
        m: render_gradient(scene, "occluder.translate.x", method=m, spp=4, seed=0, **opts)
        for m, opts in (("naive", {}), ("reparam", {}), ("finite_difference", {"h": 0.05}))
    }
    return primal, gradients


def _rgb(path):
    return mpimg.imread(path)[..., :3].astype(np.float64)


def test01_image_and_gradient_pngs(tmp_path, small):
    primal, gradients = small
    image = _rgb(plot.plot_image(primal, tmp_path / "primal.png"))
    assert image.shape[0] > 200 and image.shape[1] > 200 and np.mean(np.any(image < 0.9, axis=-1)) > 0.2
    grad = _rgb(plot.plot_gradient(gradients["reparam"], tmp_path / "grad.png"))
    red = grad[..., 0] - grad[..., 2] > 0.2
    blue = grad[..., 2] - grad[..., 0] > 0.2
    assert red.sum() > 100 and blue.sum() > 100  # a sideways move darkens one side and lightens the other


def test02_panel_side_by_side(tmp_path, small):
    primal, gradients = small
    columns = {
        "naive": gradients["naive"],
        "reparam": gradients["reparam"],
        "finite differences": gradients["finite_difference"],
    }
    path = plot.plot_panel(primal, columns, tmp_path / "panel.png", title="tiny")
    rgb = _rgb(path)
    assert path.stat().st_size > 10_000 and rgb.shape[1] > 3 * rgb.shape[0] / 2
    assert np.mean(np.any(rgb < 0.9, axis=-1)) > 0.1
