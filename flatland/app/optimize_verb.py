"""The ``optimize`` verb of the command line (:mod:`flatland.app.cli`): parameters from a target image.

``optimize SCENE --param P [--param P2 ...] (--target FILE.npy | --target-theta V [V ...])`` runs the
package's ``optimize`` (flatland: :func:`flatland.optimize.optimize`, Adam on the L2 image loss) from
the scene as given, and writes to ``--out``: ``NAME_optimize_METHOD_images.png`` (target, initial and
optimised images), ``NAME_optimize_METHOD_loss.png`` (the loss against the step and the wall time)
and ``NAME_optimize_METHOD.csv`` (per step: loss, seconds, θ of each parameter). The target is an
``.npy`` image of the camera's pixels (a plain array, or the structured array ``render`` writes,
whose field ``value`` is used), or the scene rendered at the offsets ``--target-theta``, one per
``--param``, at ``--target-spp`` samples with ``--seed`` (the run's renders use seeds derived from it).
A package without ``optimize`` (:attr:`Package.optimize <flatland.app.cli.Package>` None) refuses
the verb with one line.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flatland.app.commands import UsageError, _load_scene, _progress, _stem
from flatland.core.validate import ValidationError

if TYPE_CHECKING:
    from flatland.app.cli import Package

__all__ = ["add_optimize", "verb_optimize"]


def add_optimize(verbs: Any, pkg: Package, common: Any, scene_arg: Any) -> None:
    """The ``optimize`` subcommand and its options."""
    p = verbs.add_parser("optimize", help="recover --param values from a target image: Adam, images and loss")
    scene_arg(p)
    p.add_argument(
        "--param", action="append", default=None, required=True,
        help="a parameter to recover (repeat for several), e.g. occluder.translate.x (no default: required)",
    )  # fmt: skip
    p.add_argument("--target", default=None, help="target image: .npy of the camera's pixels (default: none)")
    p.add_argument(
        "--target-theta", type=float, nargs="+", default=None,
        help="or render the target at these offsets, one per --param (default: none)",
    )  # fmt: skip
    p.add_argument(
        "--target-spp", type=int, default=1024, help="samples per pixel of --target-theta (default 1024)"
    )
    p.add_argument("--steps", type=int, default=100, help="Adam steps (default 100)")
    p.add_argument("--lr", type=float, default=0.02, help="first step size per parameter (default 0.02)")
    p.add_argument("--decay", type=float, default=0.1, help="the step shrinks to lr x decay (default 0.1)")
    p.add_argument(
        "--method", default="reparam", choices=pkg.methods.names, help="gradient method (default reparam)"
    )
    common(p, "samples per pixel of each render (default 64)", 64)
    p.set_defaults(func=verb_optimize)


def _read_target(path: str) -> np.ndarray:
    """The target image in ``path``: a float array, or the field ``value`` of a structured one."""
    try:
        data = np.load(path, allow_pickle=False)
    except ValueError as e:
        raise ValidationError("target", f"{path}: not a numeric .npy array ({e})") from None
    if data.dtype.names is not None:
        if "value" not in data.dtype.names:
            raise ValidationError("target", f"{path}: a structured array needs a field 'value'")
        data = data["value"]
    return np.asarray(data, dtype=np.float64) if data.dtype.kind in "iuf" else data


def verb_optimize(pkg: Package, args: argparse.Namespace) -> int:
    """``optimize SCENE --param P ...``: the run's images, loss curves and history."""
    if pkg.optimize is None:
        raise UsageError(
            f"optimize: {pkg.name} has no optimize yet (it needs the derivatives of every parameter from"
            " one render_gradient call, which takes one parameter here)"
        )
    scene = _load_scene(pkg, args.scene)
    if (args.target is None) == (args.target_theta is None):
        raise UsageError("optimize: give exactly one of --target FILE.npy and --target-theta V [V ...]")
    if args.target is not None:
        targets = [_read_target(args.target)]
    else:
        if len(args.target_theta) != len(args.param):
            raise ValidationError(
                "target-theta", f"needs one offset per --param ({len(args.param)}), got {args.target_theta}"
            )
        targets = pkg.render_targets(
            scene, args.param, args.target_theta, spp=args.target_spp, seed=args.seed
        )
    start = time.perf_counter()
    result = pkg.optimize(
        scene, args.param, targets, method=args.method, steps=args.steps, lr=args.lr, decay=args.decay,
        spp=args.spp, seed=args.seed, progress=_progress(args),
    )  # fmt: skip
    seconds = time.perf_counter() - start
    from flatland.plotting.films import save_png  # matplotlib only once there is a figure to draw
    from flatland.plotting.optimize import plot_loss_curves, plot_optimize_images

    out, name = Path(args.out), f"{_stem(args.scene)}_optimize_{args.method}"
    title = f"{_stem(args.scene)}: {', '.join(args.param)}, {args.method}, {args.steps} steps, {args.spp} spp"
    images = save_png(plot_optimize_images(result, title=title), out / f"{name}_images.png")
    loss = save_png(plot_loss_curves({args.method: result}, title=title), out / f"{name}_loss.png")
    table = np.column_stack([np.arange(result.loss.size), result.loss, [*result.seconds, 0.0], result.theta])
    csv = out / f"{name}.csv"
    header = ",".join(["step", "loss", "seconds", *result.params])
    np.savetxt(csv, table, delimiter=",", header=header, comments="", fmt="%.10g")
    for p, value in result.final.items():
        print(f"{p} = {value:+.6f}")
    print(f"loss {result.loss[0]:.4g} -> {result.loss[-1]:.4g} in {result.steps} steps ({seconds:.1f} s)")
    print(f"wrote {images}, {loss} and {csv} (columns {header}; the last row's seconds: 0, no step)")
    return 0
