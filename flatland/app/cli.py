"""The command line shared by both packages: ``python -m flatland …`` and ``python -m sphere3d …``.

Verbs (the same in both packages; implemented in :mod:`flatland.app.commands`):

``demo``
    The package's default scene as the side-by-side panel "primal | naive | boundary
    | reparam | finite differences" (methods the package lacks are left out), written
    to ``--out``, and a table of each method's error against a reference; packages
    may append further sections (flatland: the textbook table).
``render SCENE``
    The image as PNG and ``.npy`` (structured array with fields ``value``, ``value_stderr``).
``gradient SCENE --param P --method M``
    The derivative image as PNG and ``.npy`` (structured array with fields
    ``value``, ``value_stderr``, ``derivative``, ``derivative_stderr``, as render's
    ``value``, ``value_stderr``). Without ``--param`` it names the scene's parameters.
``study CONFIG``
    A study (:mod:`flatland.app.study`): CSV and figures in ``--out``.
``optimize SCENE --param P [--param P2 ...] (--target FILE.npy | --target-theta V ...)``
    Recover the parameters from a target image by Adam (:mod:`flatland.app.optimize_verb`): the
    images, the loss curve and the history in ``--out``.

``SCENE`` is a built-in scene name (listed by ``render --help``) or a JSON file;
``--method`` offers the methods of the package's method table. Without a verb the
command prints its help, the verbs with one line each (status 0); ``VERB --help``
lists the verb's options, each with its default.

Two kinds of failure, told apart by the exit status:

* a user's mistake (a bad argument, or a missing, unreadable, malformed or invalid
  scene file or configuration: argparse errors, :class:`ValidationError` and
  :class:`OSError`) prints one line ``error: <what is wrong>`` on stderr and exits
  with status 2 (:data:`EXIT_USAGE`), never a traceback;
* any other exception is a bug: its traceback and a last line ``internal error:
  ...`` go to stderr and the status is 1 (:data:`EXIT_INTERNAL`).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from flatland.app.commands import UsageError, verb_demo, verb_gradient, verb_render, verb_study
from flatland.app.optimize_verb import add_optimize
from flatland.core.contract import MethodTable
from flatland.core.validate import ValidationError, check_int, check_seed

__all__ = ["EXIT_INTERNAL", "EXIT_USAGE", "Package", "main"]

EXIT_USAGE = 2
"""Exit status for bad arguments, scene files or configurations."""
EXIT_INTERNAL = 1
"""Exit status for an internal error (an exception that is not a user's mistake)."""


@dataclass(frozen=True)
class Package:
    """Everything the application layer (CLI and study runner) knows about a package.

    Each package's ``__main__`` builds one and passes it to :func:`main`; nothing is
    imported by name.

    Attributes
    ----------
    name : str
        The package's name, shown in messages and ``--help``, and part of a study's
        cache key.
    load_scene, list_scenes, parameter_names : callable
        The package's scene API: a scene from a name, dict or JSON file (every bad
        source a :class:`ValidationError`); the built-in scene names; a scene's
        parameter names.
    render, render_gradient, irradiance : callable
        The package's rendering API (``render(scene, spp=, seed=, batches=, progress=)``,
        ``render_gradient(scene, param, method=, spp=, seed=, batches=, progress=, **options)``;
        ``progress`` as in :mod:`flatland.core.progress`: the command line passes False for
        ``--quiet``, else None, a bar when stderr is a terminal).
    methods : MethodTable
        The gradient methods of ``render_gradient`` and their options.
    demo_scene, demo_param : str
        The embedded default scene of ``demo`` and the parameter it differentiates.
    demo_spp : int
        Default samples per pixel of ``demo``; the reference uses ``reference_factor``
        times as many.
    reference_factor : int
        Sample multiplier of the demo's reference.
    reference_options : tuple of (name, value) pairs
        Options of the demo's reference method (e.g. a larger finite-difference step ``h``,
        trading an $O(h^2)$ bias for less variance).
    demo_methods : tuple of str, optional
        The panel's gradient methods, in order; None: those of
        :data:`~flatland.app.commands.DEMO_METHODS` the package has.
    reference_method : str, optional
        A study's default reference method, and the demo's unless ``demo_reference`` is
        given; None: ``boundary`` if the package has it, else ``finite_difference``.
    demo_reference : str, optional
        The method of the demo's reference when it differs from a study's: a study's
        reference judges small pixel integrals at many samples, where a method that is
        cheap on a whole film can be the costly one (None: as ``reference_method``).
    demo_sections : tuple of callables
        Extra text sections printed by ``demo``, each called with the parsed arguments.
    studies : mapping
        Built-in study configurations by name: ``study NAME`` runs one when no file
        ``NAME`` exists.
    integrals, estimate, estimators : optional
        Textbook integrals by name (objects with ``name``, ``default_theta``,
        ``check_theta`` and ``derivative``), their estimator ``estimate(integral, theta,
        method=, n=, seed=, **options)`` and its :class:`MethodTable`, for study
        problems ``{"integral": ...}``; None where the package offers none.
    plot_image, plot_gradient, plot_panel, plot_study : callable, optional
        Figure writers; None (the default) draws with the shared
        :mod:`flatland.plotting.films` and :mod:`flatland.plotting.study`, imported
        (with matplotlib) only when there is a figure to draw.
    films : tuple of str
        The package's films (``render(..., film=)``), the default first: ``render`` and
        ``gradient`` then take ``--film`` (checked by the package's own renderer: a bad
        value is one :class:`ValidationError`). Empty (the default): no such option.
    cluster : bool
        The package's ``render`` and ``render_gradient`` take ``scheduler=`` (a ``dask.distributed``
        scheduler address): ``render`` and ``gradient`` then take ``--scheduler``. False (the
        default): no such option.
    optimize, render_targets : callable, optional
        The package's ``optimize(scene, params, targets, method=, steps=, lr=, decay=, spp=, seed=,
        progress=)`` (:func:`flatland.optimize.optimize`) and ``render_targets(scene, params, theta,
        spp=, seed=)``; None: the ``optimize`` verb refuses with one line.
    sketch : callable, optional
        ``sketch(ax, scene, param)`` draws a scene (and what ``param`` moves; None:
        nothing) into a matplotlib Axes; the figures of ``demo``, ``render`` and
        ``gradient`` then show it in a left panel, the scene beside its film. None:
        no sketch.
    """

    name: str
    load_scene: Callable[[Any], Any]
    list_scenes: Callable[[], Sequence[str]]
    parameter_names: Callable[[Any], Sequence[str]]
    render: Callable[..., Any]
    render_gradient: Callable[..., Any]
    irradiance: Callable[..., Any]
    methods: MethodTable
    demo_scene: str
    demo_param: str
    demo_spp: int = 64
    reference_factor: int = 16
    reference_options: tuple[tuple[str, Any], ...] = ()
    demo_methods: tuple[str, ...] | None = None
    reference_method: str | None = None
    demo_reference: str | None = None
    demo_sections: tuple[Callable[[argparse.Namespace], str], ...] = ()
    studies: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    integrals: Mapping[str, Any] | None = None
    estimate: Callable[..., Any] | None = None
    estimators: MethodTable | None = None
    plot_image: Callable[..., Path] | None = None
    plot_gradient: Callable[..., Path] | None = None
    plot_panel: Callable[..., Path] | None = None
    plot_study: Callable[..., list[Path]] | None = None
    sketch: Callable[[Any, Any, str | None], Any] | None = None
    films: tuple[str, ...] = ()
    cluster: bool = False
    optimize: Callable[..., Any] | None = None
    render_targets: Callable[..., Any] | None = None

    def plot(self, kind: str) -> Callable[..., Any]:
        """The figure writer ``plot_<kind>``: the package's own, else the shared one (imported now)."""
        own = getattr(self, f"plot_{kind}")
        if own is not None:
            return own
        from flatland.plotting import films, study  # matplotlib only once there is a figure to draw

        return getattr(study if kind == "study" else films, f"plot_{kind}")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog.split()[-1]}: {message}")


# ---------------------------------------------------------------------------------------------- helpers
def _check_counts(args: argparse.Namespace) -> None:
    """Counts and seed parsed as plain ints are checked here, so errors read ``spp: must be ...``."""
    for name in ("spp", "batches", "probes", "workers", "steps", "target_spp"):
        if getattr(args, name, None) is not None:
            check_int(name, getattr(args, name))
    if args.seed is not None:
        check_seed("seed", args.seed)


# ------------------------------------------------------------------------------------------------ parser
def _parser(pkg: Package) -> _Parser:
    parser = _Parser(
        prog=f"python -m {pkg.name}",
        description=f"{pkg.name}: differentiable rendering of discontinuous integrands "
        "(Loubet, Holzschuch, Jakob 2019). Errors print one line and exit with status 2.",
        epilog=f"python -m {pkg.name} VERB --help lists a verb's options and their defaults.",
    )
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=_Parser)

    def common(
        p: argparse.ArgumentParser, spp_help: str, spp_default: int | None, seed: int | None = 0
    ) -> None:
        seed_help = (
            "random seed (default 0)"
            if seed is not None
            else "replace the configuration's seed (default: keep it)"
        )
        p.add_argument("--seed", type=int, default=seed, help=seed_help)
        p.add_argument("--spp", type=int, default=spp_default, help=spp_help)
        p.add_argument("--out", default="out", help="output folder (default ./out)")
        p.add_argument(
            "--quiet", action="store_true", help="no progress bar (default: a bar when stderr is a terminal)"
        )

    scenes = ", ".join(pkg.list_scenes())

    def scene_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument("scene", metavar="SCENE", help=f"a JSON scene file or a built-in scene: {scenes}")
        p.add_argument(
            "--batches", type=int, default=None,
            help="independent batches behind the standard errors (default: the largest divisor of --spp"
            " up to 16)",
        )  # fmt: skip
        if pkg.films:
            choices = " or ".join(pkg.films)
            p.add_argument("--film", default=None, help=f"{choices} (default {pkg.films[0]})")
        if pkg.cluster:
            p.add_argument(
                "--scheduler", default=None,
                help="dask.distributed scheduler address: the image's tiles run on that cluster, bit for bit"
                " the local image (default: none, on this machine)",
            )  # fmt: skip

    def depth_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--max-depth", type=int, default=None,
            help="path vertices (default 1: direct light only); reparam and boundary take only 1",
        )  # fmt: skip

    demo = verbs.add_parser("demo", help="the default scene: panel of methods and error table (< 1 min)")
    common(demo, f"samples per pixel (default {pkg.demo_spp})", None)
    demo.set_defaults(func=verb_demo)

    render = verbs.add_parser("render", help="render SCENE to PNG and .npy")
    scene_arg(render)
    depth_arg(render)
    common(render, "samples per pixel (default 64)", 64)
    render.set_defaults(func=verb_render)

    gradient = verbs.add_parser("gradient", help="derivative image of SCENE w.r.t. --param, PNG and .npy")
    scene_arg(gradient)
    depth_arg(gradient)
    gradient.add_argument(
        "--param", default=None,
        help="scene parameter, e.g. occluder.translate.x (no default: omit it to list the scene's)",
    )  # fmt: skip
    methods = pkg.methods.names
    gradient.add_argument(
        "--method", default="reparam", choices=methods, help="gradient method (default reparam)"
    )
    gradient.add_argument(
        "--kappa", type=float, default=None,
        help=f"reparam: convolution kernel concentration (default {_default(pkg, 'reparam', 'kappa')})",
    )  # fmt: skip
    gradient.add_argument(
        "--probes", type=int, default=None,
        help=f"reparam: probe rays per kernel (default {_default(pkg, 'reparam', 'probes')})",
    )  # fmt: skip
    gradient.add_argument(
        "--paired",
        action="store_true",
        help="reparam: paired samples sharing one transform (default off; see docs/theory/kernels.md)",
    )
    gradient.add_argument(
        "--h", type=float, default=None,
        help=f"finite_difference: step (default {_default(pkg, 'finite_difference', 'h')})",
    )  # fmt: skip
    common(gradient, "samples per pixel (default 64)", 64)
    gradient.set_defaults(func=verb_gradient)

    study = verbs.add_parser("study", help="run a study CONFIG (JSON file or built-in name): CSV and figures")
    builtin = f"; built-in: {', '.join(pkg.studies)}" if pkg.studies else ""
    study.add_argument("config", metavar="CONFIG", help=f"study configuration: a JSON file{builtin}")
    study.add_argument(
        "--workers", type=int, default=None, help="worker processes (default: the configuration's, else 1)"
    )
    study.add_argument(
        "--scheduler", default=None,
        help="dask.distributed scheduler address (default: none, the trials run on this machine)",
    )  # fmt: skip
    study.add_argument("--cache-dir", default=None, help="reference cache (default OUT/.cache/reparam-lab)")
    common(study, "replace every cell's samples per trial, n or spp (default: keep them)", None, seed=None)
    study.set_defaults(func=verb_study)
    add_optimize(verbs, pkg, common, scene_arg)
    return parser


def _default(pkg: Package, method: str, option: str) -> str:
    """A method option's default as ``--help`` states it: its ``default_text``, else its value."""
    spec = pkg.methods.get(method)
    if spec is None or option not in spec.options:
        return "none"
    if spec.options[option].default_text:
        return spec.options[option].default_text
    value = spec.options[option].default
    if value is None:
        return "chosen by the method"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _one_line(error: BaseException) -> str:
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        message = f"{error.filename}: {error.strerror}"
    else:
        message = str(error) or type(error).__name__
    return " ".join(message.split())


def main(package: Package, argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``) and run the verb; returns the exit status.

    A user's mistake (argparse error, :class:`ValidationError`, :class:`OSError`)
    prints one line and returns :data:`EXIT_USAGE`; any other exception prints its
    traceback and an ``internal error`` line and returns :data:`EXIT_INTERNAL`.
    """
    try:
        parser = _parser(package)
        args = parser.parse_args(argv)
        if args.verb is None:  # no verb: what there is to do
            parser.print_help()
            return 0
        _check_counts(args)
        return args.func(package, args)
    except UsageError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except (ValidationError, OSError) as e:  # bad input; missing or unwritable files, unreachable cluster
        print(f"error: {_one_line(e)}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as e:  # --help
        return e.code if isinstance(e.code, int) else 0
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # e.g. a ValueError deep in numpy, a MemoryError: never reported as a usage error
        traceback.print_exc(file=sys.stderr)
        print(
            f"internal error: {type(e).__name__} in python -m {package.name}: {_one_line(e)} (an unexpected"
            " exception, not a problem found in the arguments; the traceback above shows where)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL
