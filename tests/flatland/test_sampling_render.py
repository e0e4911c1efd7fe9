"""The renderer's samplers: pixel filters, plain and blurred; emitter directions; the light mixture.

Chi-square goodness of fit with 51 bins (odd) over 200 000 samples per case. The family
of cases rejects a correct sampler with probability ALPHA = 1e-3 overall: each case is
tested at the Šidák level sidak(ALPHA, number of cases). Seeds are fixed. A wrong
density (a missing |cos| factor, a cone of the wrong width) gives p-values far below
1e-10 with this many samples.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import integrate

from flatland import sampling as s
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof, chi2_gof_counts, sidak
from flatland.integrator import filter_blurred, filter_sample, filter_value
from flatland.lights import Lights
from flatland.scene import bind, load_scene

N = 200_000
BINS = 51
ALPHA = 1e-3

X = np.array([0.2, -0.3])
A, B = np.array([-1.0, 1.5]), np.array([2.0, 0.8])
C, R = np.array([1.0, 2.0]), 0.7

LIGHTS_SCENE = {
    "name": "lights",
    "camera": {"position": [0.0, -2.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 4},
    "shapes": [
        {
            "name": "wide",
            "type": "segment",
            "points": [[-2.0, 1.0], [1.0, 1.0]],
            "emission": 1.0,
            "fade": 0.25,
        },
        # behind the first one as seen from X: the mixture density adds both where they overlap
        {"name": "far", "type": "segment", "points": [[0.0, 3.0], [2.5, 2.0]], "emission": 3.0},
        {"name": "ball", "type": "circle", "center": [-1.5, -0.5], "radius": 0.4, "emission": 2.0},
        {"name": "dark", "type": "segment", "points": [[0.5, 0.2], [0.9, 0.4]]},
    ],
}


def _lights_case():
    lights = Lights.of(bind(load_scene(LIGHTS_SCENE)))

    def sample(u):
        v = stream(7, "lights").random((u.size, 2))
        # angles are defined modulo 2π (the ball's cone straddles ±π): wrap them for the histogram
        return s.wrap_angle(lights.sample(v[:, 0], u, np.tile(X, (u.size, 1)))[0])

    return sample, lambda phi: lights.pdf(phi, np.broadcast_to(X, (*np.shape(phi), 2))), (-np.pi, np.pi)


def _blurred_case(kind):
    width, sigma = 0.3, 0.08

    def sample(u):
        z = stream(7, "blur", kind == "tent").standard_normal(u.size)
        return filter_sample(kind, u, 0.0, width) + sigma * z

    return sample, lambda y: filter_blurred(kind, y, width, sigma), (-0.6, 0.6)


def _filter_case(kind):
    w = 0.3  # the Gaussian's mass beyond its 4 sigma (= 2 w) is pooled into one cell
    support = {"box": (-0.5 * w, 0.5 * w), "tent": (-w, w), "gaussian": (-2.0 * w, 2.0 * w)}
    return lambda u: filter_sample(kind, u, 0.0, w), lambda t: filter_value(kind, t, 0.0, w), support[kind]


CASES = {
    # histogram ranges are the densities' supports, so no bin straddles a jump
    "filter_box": _filter_case("box"),
    "filter_tent": _filter_case("tent"),
    "filter_gaussian": _filter_case("gaussian"),
    "segment_direction": (
        lambda u: s.sample_segment_direction(u, X, A, B),
        lambda phi: s.pdf_segment_direction(phi, X, A, B),
        (np.arctan2(*(B - X)[::-1]), np.arctan2(*(A - X)[::-1])),
    ),
    "circle_direction": (
        lambda u: s.sample_circle_direction(u, X, C, R),
        lambda phi: s.pdf_circle_direction(phi, X, C, R),
        (
            np.arctan2(*(C - X)[::-1]) - np.arcsin(R / np.linalg.norm(C - X)),
            np.arctan2(*(C - X)[::-1]) + np.arcsin(R / np.linalg.norm(C - X)),
        ),
    ),
    "light_mixture": _lights_case(),
    "blurred_tent": _blurred_case("tent"),
    "blurred_gaussian": _blurred_case("gaussian"),
}

LEVEL = sidak(ALPHA, len(CASES))


@pytest.mark.parametrize("name", list(CASES))
def test01_pdf_integrates_to_one(name):
    _, pdf, (lo, hi) = CASES[name]
    x = (
        np.linspace(lo - 1.0, hi + 1.0, 400_001)
        if name.startswith(("blurred", "filter"))
        else np.linspace(-np.pi, np.pi, 400_001)
    )
    total = integrate.trapezoid(pdf(x), x)
    assert abs(total - 1.0) < 2e-3, total


@pytest.mark.parametrize("name", list(CASES))
def test02_sampler_draws_from_its_pdf(name):
    sample, pdf, rng = CASES[name]
    u = stream(11, "chi2", list(CASES).index(name)).random(N)
    if name == "light_mixture":
        # a density with jumps at every emitter's ends: expected counts by adaptive quadrature
        edges = np.linspace(*rng, BINS + 1)
        mass = [
            integrate.quad(lambda p: float(pdf(np.array(p))), a, b, limit=200)[0]
            for a, b in itertools.pairwise(edges)
        ]
        observed, _ = np.histogram(sample(u), edges)
        result = chi2_gof_counts(observed, N * np.array(mass))
    else:
        result = chi2_gof(sample(u), pdf, BINS, rng)
    assert result.passed(LEVEL), (name, result)


def test03_segment_density_matches_the_change_of_measure():
    """dφ = |cos θ_y| dℓ / |x - y| (theory/radiometry): density |x - y| / (ℓ |cos θ_y|) toward y."""
    u = np.array([0.1, 0.5, 0.9])
    y = A + u[:, None] * (B - A)
    phi = s.sample_segment_direction(u, X, A, B)
    e = (B - A) / np.linalg.norm(B - A)
    n = np.array([-e[1], e[0]])
    d = y - X
    dist = np.linalg.norm(d, axis=1)
    expected = dist / (np.linalg.norm(B - A) * np.abs(d @ n) / dist)
    assert np.allclose(s.pdf_segment_direction(phi, X, A, B), expected)
    # behind the origin and beside the segment: zero
    assert s.pdf_segment_direction(np.array([-np.pi / 2, 0.0]), X, A, B).tolist() == [0.0, 0.0]
