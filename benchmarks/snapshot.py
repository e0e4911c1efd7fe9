"""Hashes of every method's images on a grid of scenes, parameters and options: the check that a
restructure changed no number (``python -m benchmarks.snapshot > before.json``, then compare).

Hashes are of float64 bytes, so they compare runs on one machine and library build, not across
machines (a different CPU may round differently).
"""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

import flatland as fl
import sphere3d as s3

S3_CASES = [
    # scene, parameter, method, options
    ("hard_shadow", "occluder.translate.x", "reparam", {}),
    ("hard_shadow", "occluder.translate.x", "naive", {}),
    ("hard_shadow", "occluder.translate.x", "boundary", {}),
    ("hard_shadow", "occluder.translate.z", "reparam", {}),
    ("hard_shadow", "occluder.rotate.z", "reparam", {}),
    ("hard_shadow", "light.translate.x", "reparam", {}),
    ("hard_shadow", "light.translate.x", "boundary", {}),
    ("hard_shadow_cube", "occluder.translate.x", "reparam", {}),
    ("hard_shadow_cube", "occluder.rotate.z", "reparam", {}),
    ("hard_shadow_cube", "occluder.translate.x", "boundary", {}),
    ("hard_shadow_cube", "occluder.scale", "reparam", {}),
    ("shadow", "occluder.translate.x", "reparam", {}),
    ("shadow", "occluder.translate.x", "reparam", {"paired": True}),
    ("shadow", "occluder.translate.x", "reparam", {"kappa": None}),
    ("shadow", "occluder.translate.x", "reparam", {"refine": 0, "probes": 1, "emitter_probes": 1}),
    ("shadow", "occluder.translate.x", "reparam", {"variant": "paper"}),
    ("hard_shadow", "occluder.translate.x", "reparam", {"variant": "paper"}),
    ("shadow", "occluder.translate.x", "finite_difference", {}),
    ("shadow", "occluder.albedo", "reparam", {}),
    ("shadow", "camera.translate.x", "reparam", {}),
    ("shadow", "camera.translate.x", "boundary", {}),
    ("silhouette", "occluder.translate.x", "reparam", {}),
    ("silhouette", "occluder.rotate.x", "boundary", {}),
    ("sky", "occluder.translate.z", "reparam", {}),
    ("sky", "occluder.translate.z", "reparam", {"paired": True}),
    ("sky", "sky.emission", "reparam", {}),
    ("sky", "occluder.translate.z", "boundary", {}),
    ("two_occluders", "right.translate.x", "reparam", {}),
    ("two_occluders", "light.emission", "reparam", {}),
    ("two_occluders", "right.translate.x", "boundary", {}),
]
FL_SCENES = ["shadow", "penumbra", "polygon", "silhouette", "two_occluders"]
FL_METHODS = [
    ("naive", {}),
    ("reparam", {}),
    ("reparam", {"paired": True, "kappa": 1000.0}),
    ("boundary", {}),
    ("finite_difference", {}),
]


def digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def main() -> None:
    out: dict[str, str] = {}
    for scene, param, method, options in S3_CASES:
        for film in ("splat", "pixel"):
            g = s3.render_gradient(scene, param, method=method, spp=8, seed=3, film=film, **options)
            key = f"s3 {scene} {param} {method} {options} {film}"
            out[key] = digest(g.value, g.derivative, g.derivative_stderr)
            print(key, out[key], file=sys.stderr)
    for method, options in [("naive", {}), ("reparam", {}), ("reparam", {"paired": True}), ("boundary", {})]:
        e = s3.irradiance(
            "sky", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "occluder.translate.z", method, n=4096, seed=5, **options
        )
        out[f"s3 irradiance {method} {options}"] = digest([e.value, e.derivative, e.derivative_stderr])
    for scene in FL_SCENES:
        loaded = fl.load_scene(scene)
        params = [*list(loaded.parameters[:2]), "camera.translate.x"]
        for param in params:
            for method, options in FL_METHODS:
                g = fl.render_gradient(scene, param, method=method, spp=16, seed=2, **options)
                out[f"fl {scene} {param} {method} {options}"] = digest(
                    g.value, g.derivative, g.derivative_stderr
                )
    from flatland.integrals import INTEGRALS

    for name in INTEGRALS:
        for method in ("naive", "reparam", "boundary", "finite_difference"):
            e = fl.estimate(name, theta=0.5, method=method, n=4096, seed=1)
            out[f"fl textbook {name} {method}"] = digest([e.value, e.derivative, e.derivative_stderr])
    json.dump(out, sys.stdout, indent=1, sort_keys=True)
    print()


if __name__ == "__main__":
    main()
