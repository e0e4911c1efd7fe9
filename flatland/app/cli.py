"""The command line shared by both packages: ``python -m flatland …`` and ``python -m sphere3d …``.

Verbs (the same in both packages):

``demo``
    The package's default scene as the side-by-side panel "primal | naive | boundary
    | reparam | finite differences" (methods the package lacks are left out), written
    to ``--out``, and a table of each method's error against a reference; packages
    may append further sections (flatland: the textbook table).
``render SCENE``
    The image as PNG and ``.npy``.
``gradient SCENE --param P --method M``
    The derivative image as PNG and ``.npy`` (structured array with fields
    ``value``, ``value_stderr``, ``derivative``, ``derivative_stderr``). Without
    ``--param`` it names the scene's parameters.
``study CONFIG``
    A study (:mod:`flatland.app.study`): CSV and figures in ``--out``.

``SCENE`` is a built-in scene name (listed by ``render --help``) or a JSON file;
``--method`` offers the methods of the package's method table.

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
import math
import os
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from flatland.app.table import error_table, method_label
from flatland.core.contract import MethodTable
from flatland.core.stats import z_score
from flatland.core.validate import ValidationError, check_int, check_positive, check_seed

__all__ = ["EXIT_INTERNAL", "EXIT_USAGE", "Package", "main"]

EXIT_USAGE = 2
"""Exit status for bad arguments, scene files or configurations."""
EXIT_INTERNAL = 1
"""Exit status for an internal error (an exception that is not a user's mistake)."""

DEMO_METHODS = ("naive", "boundary", "reparam", "finite_difference")
"""Panel columns after the primal, in order (those the package has)."""
PANEL_TITLES = {"finite_difference": "finite differences"}


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
        The package's rendering API (``render(scene, spp=, seed=, batches=)``,
        ``render_gradient(scene, param, method=, spp=, seed=, batches=, **options)``).
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
        Options of the reference method (e.g. a larger finite-difference step ``h``,
        trading an O(h²) bias for less variance).
    demo_methods : tuple of str, optional
        The panel's gradient methods, in order; None: those of :data:`DEMO_METHODS` the
        package has.
    reference_method : str, optional
        The method of the demo's reference and a study's default reference; None:
        ``boundary`` if the package has it, else ``finite_difference``.
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
        :mod:`flatland.app.plotting`, imported (with matplotlib) only when there is a
        figure to draw.
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
    demo_sections: tuple[Callable[[argparse.Namespace], str], ...] = ()
    studies: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    integrals: Mapping[str, Any] | None = None
    estimate: Callable[..., Any] | None = None
    estimators: MethodTable | None = None
    plot_image: Callable[..., Path] | None = None
    plot_gradient: Callable[..., Path] | None = None
    plot_panel: Callable[..., Path] | None = None
    plot_study: Callable[..., list[Path]] | None = None

    def plot(self, kind: str) -> Callable[..., Any]:
        """The figure writer ``plot_<kind>``: the package's own, else the shared one (imported now)."""
        own = getattr(self, f"plot_{kind}")
        if own is not None:
            return own
        from flatland.app import plotting  # matplotlib only once there is a figure to draw

        return getattr(plotting, f"plot_{kind}")


class _UsageError(Exception):
    """An argparse error, reported as one line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{self.prog.split()[-1]}: {message}")


# ---------------------------------------------------------------------------------------------- helpers
def _check_counts(args: argparse.Namespace) -> None:
    """Counts and seed parsed as plain ints are checked here, so errors read ``spp: must be ...``."""
    for name in ("spp", "batches", "probes", "workers"):
        if getattr(args, name, None) is not None:
            check_int(name, getattr(args, name))
    if args.seed is not None:
        check_seed("seed", args.seed)


def _load_scene(pkg: Package, source: str) -> Any:
    """The scene ``source`` (name or JSON file); every bad source is a ValidationError."""
    return pkg.load_scene(source)


def _stem(source: str) -> str:
    return Path(source).stem if source.endswith(".json") else source


def _save_fields(path: Path, **fields: np.ndarray) -> Path:
    """One ``.npy`` holding a structured array with one float64 field per keyword."""
    shape = np.shape(next(iter(fields.values())))
    out = np.empty(shape, dtype=[(k, np.float64) for k in fields])
    for k, v in fields.items():
        out[k] = v
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, out)
    return path


def _options(args: argparse.Namespace) -> dict[str, Any]:
    """Method options given on the command line (unset ones are left to the method's defaults)."""
    options = {}
    if args.kappa is not None:
        options["kappa"] = check_positive("kappa", args.kappa)
    if args.probes is not None:
        options["probes"] = args.probes
    if args.paired:
        options["paired"] = True
    if args.h is not None:
        options["h"] = check_positive("h", args.h)
    return options


def _reference_needed(gradients: Mapping[str, Any], reference: Any, ref_spp: int) -> int | None:
    """Reference spp that makes its film-sum stderr 1/4 of the smallest unbiased method's (x 1.25
    for the scatter of the estimated errors), or None if it already is."""
    from flatland.core.bias import REFERENCE_RATIO, reference_spp_needed

    ref_se = float(np.sqrt(np.sum(np.square(reference.derivative_stderr))))
    ratio = _reference_ratio(gradients, reference)
    if ratio <= REFERENCE_RATIO:
        return None
    return reference_spp_needed(ref_spp, ref_se, ref_se / ratio)


def _reference_ratio(gradients: Mapping[str, Any], reference: Any) -> float:
    """Reference film-sum stderr / the smallest among the methods the bias tests do not flag (a flag
    already counts the reference's noise in its z); 0 when there is none."""
    from flatland.core.bias import Z_FLAG

    def se(g: Any) -> float:
        return float(np.sqrt(np.sum(np.square(g.derivative_stderr))))

    judged = []
    for g in gradients.values():
        z = z_score(
            float(np.sum(g.derivative)), float(np.sum(reference.derivative)), math.hypot(se(g), se(reference))
        )
        if abs(z) <= Z_FLAG and se(g) > 0.0:
            judged.append(se(g))
    return se(reference) / min(judged) if judged else 0.0


def _film_sum(g: Any) -> str:
    """Σ_j dI_j/dθ ± its standard error (pixels estimated independently)."""
    total = float(np.sum(g.derivative))
    stderr = float(np.sqrt(np.sum(np.square(g.derivative_stderr))))
    return f"{total:+.4g} ± {stderr:.2g}"


# ------------------------------------------------------------------------------------------------ verbs
def _demo(pkg: Package, args: argparse.Namespace) -> int:
    spp = args.spp or pkg.demo_spp
    seed = args.seed
    scene = _load_scene(pkg, pkg.demo_scene)
    table = pkg.methods
    methods = list(pkg.demo_methods or [m for m in DEMO_METHODS if m in table.names])
    reference_method = pkg.reference_method or (
        "boundary" if "boundary" in table.names else "finite_difference"
    )
    out = Path(args.out)

    start = time.perf_counter()
    primal = pkg.render(scene, spp=spp, seed=seed)
    gradients, seconds = {}, {}
    for method in methods:
        t0 = time.perf_counter()
        gradients[method] = pkg.render_gradient(scene, pkg.demo_param, method=method, spp=spp, seed=seed)
        seconds[method] = time.perf_counter() - t0
    ref_spp = pkg.reference_factor * spp
    ref_options = dict(pkg.reference_options)
    ref_label = method_label(reference_method, ref_options.items())
    reference = pkg.render_gradient(
        scene, pkg.demo_param, method=reference_method, spp=ref_spp, seed=seed + 1, **ref_options
    )
    needed = _reference_needed(gradients, reference, ref_spp)
    if needed is not None:  # the reference must be 4 × more precise than the methods it judges
        ref_spp = min(needed, 4 * ref_spp)  # at most 4 × (the ratio is printed: the cap shows there)
        reference = pkg.render_gradient(
            scene, pkg.demo_param, method=reference_method, spp=ref_spp, seed=seed + 1, **ref_options
        )
    columns = {PANEL_TITLES.get(m, m): g for m, g in gradients.items()}
    title = f"{pkg.demo_scene}: d/d {pkg.demo_param}, {spp} spp"
    panel = pkg.plot("panel")(primal, columns, out / "demo_panel.png", title=title)
    title = (
        f"{pkg.name} demo: scene {pkg.demo_scene!r}, parameter {pkg.demo_param!r}, {spp} spp, seed {seed}\n"
        f"reference: {ref_label} at {ref_spp} spp, seed {seed + 1}: Σ dI/dθ = {_film_sum(reference)}"
        f"; its stderr / the smallest unbiased method's = {_reference_ratio(gradients, reference):.2f}"
        " (required <= 0.25)"
    )
    print(error_table(gradients, seconds, reference, title))
    print(f"\nwrote {panel}  ({time.perf_counter() - start:.1f} s)")
    for section in pkg.demo_sections:
        print()
        print(section(args))
    return 0


def _render(pkg: Package, args: argparse.Namespace) -> int:
    scene = _load_scene(pkg, args.scene)
    image = pkg.render(scene, spp=args.spp, seed=args.seed, batches=args.batches)
    name = _stem(args.scene)
    out = Path(args.out)
    png = pkg.plot("image")(image, out / f"{name}.png", title=f"{name}, {args.spp} spp")
    npy = _save_fields(out / f"{name}.npy", value=image.value, stderr=image.stderr)
    print(f"wrote {png} and {npy} (fields value, stderr; film shape {image.shape})")
    return 0


def _gradient(pkg: Package, args: argparse.Namespace) -> int:
    scene = _load_scene(pkg, args.scene)
    if args.param is None:
        names = ", ".join(pkg.parameter_names(scene))
        raise _UsageError(f"gradient: --param is required; parameters of {scene.name!r}: {names}")
    g = pkg.render_gradient(
        scene, args.param, method=args.method, spp=args.spp, seed=args.seed, batches=args.batches,
        **_options(args),
    )  # fmt: skip
    name = f"{_stem(args.scene)}_{args.param}_{args.method}"  # parameter names contain dots: no with_suffix
    out = Path(args.out)
    title = f"{_stem(args.scene)}: d/d {args.param}, {args.method}, {args.spp} spp"
    png = pkg.plot("gradient")(g, out / f"{name}.png", title=title)
    npy = _save_fields(
        out / f"{name}.npy",
        value=g.value,
        value_stderr=g.value_stderr,
        derivative=g.derivative,
        derivative_stderr=g.derivative_stderr,
    )
    print(f"Σ dI/dθ over the film = {_film_sum(g)} (one standard error)")
    print(f"wrote {png} and {npy} (fields value, value_stderr, derivative, derivative_stderr)")
    return 0


def _study(pkg: Package, args: argparse.Namespace) -> int:
    from flatland.app.study import run_study
    from flatland.app.study_config import load_config

    source: Any = args.config
    if not Path(source).exists():
        if source not in pkg.studies:
            raise ValidationError(
                "study",
                f"no file {source!r} and no built-in study of that name; built-in studies: "
                + ", ".join(pkg.studies),
            )
        source = pkg.studies[args.config]
    config = load_config(source, package=pkg, seed=args.seed, samples=args.spp, name=_stem(args.config))
    out = Path(args.out)
    cache = Path(args.cache_dir) if args.cache_dir else out / ".cache" / "reparam-lab"
    result = run_study(
        config,
        workers=args.workers,
        scheduler=args.scheduler,
        cache_dir=cache,
        progress=False if args.quiet else None,
    )
    csv_path = result.to_csv(out / f"{config.name}.csv")
    figures = pkg.plot("study")(result, out)
    print(result.table())
    print(f"\nwrote {csv_path}" + "".join(f", {f}" for f in figures) + f"  ({result.seconds:.1f} s)")
    return 0


# ------------------------------------------------------------------------------------------------ parser
def _parser(pkg: Package) -> _Parser:
    parser = _Parser(
        prog=f"python -m {pkg.name}",
        description=f"{pkg.name}: differentiable rendering of discontinuous integrands "
        "(Loubet, Holzschuch, Jakob 2019). Errors print one line and exit with status 2.",
    )
    verbs = parser.add_subparsers(dest="verb", required=True, metavar="VERB", parser_class=_Parser)

    def common(
        p: argparse.ArgumentParser, spp_help: str, spp_default: int | None, seed: int | None = 0
    ) -> None:
        seed_help = "random seed (default 0)" if seed is not None else "replace the configuration's seed"
        p.add_argument("--seed", type=int, default=seed, help=seed_help)
        p.add_argument("--spp", type=int, default=spp_default, help=spp_help)
        p.add_argument("--out", default="out", help="output folder (default ./out)")
        p.add_argument("--quiet", action="store_true", help="no progress bar")

    scenes = ", ".join(pkg.list_scenes())

    def scene_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument("scene", metavar="SCENE", help=f"a JSON scene file or a built-in scene: {scenes}")
        p.add_argument("--batches", type=int, default=None, help="independent batches behind the stderr")

    demo = verbs.add_parser("demo", help="the default scene: panel of methods and error table (< 1 min)")
    common(demo, f"samples per pixel (default {pkg.demo_spp})", None)
    demo.set_defaults(func=_demo)

    render = verbs.add_parser("render", help="render SCENE to PNG and .npy")
    scene_arg(render)
    common(render, "samples per pixel (default 64)", 64)
    render.set_defaults(func=_render)

    gradient = verbs.add_parser("gradient", help="derivative image of SCENE w.r.t. --param, PNG and .npy")
    scene_arg(gradient)
    gradient.add_argument(
        "--param", default=None, help="scene parameter, e.g. occluder.translate.x (omit it to list them)"
    )
    methods = pkg.methods.names
    gradient.add_argument(
        "--method", default="reparam", choices=methods, help="gradient method (default reparam)"
    )
    gradient.add_argument(
        "--kappa", type=float, default=None, help="reparam: convolution kernel concentration"
    )
    gradient.add_argument("--probes", type=int, default=None, help="reparam: probe rays")
    gradient.add_argument(
        "--paired", action="store_true", help="reparam: paired samples sharing one transform (DESIGN 2.9)"
    )
    gradient.add_argument("--h", type=float, default=None, help="finite_difference: step")
    common(gradient, "samples per pixel (default 64)", 64)
    gradient.set_defaults(func=_gradient)

    study = verbs.add_parser("study", help="run a study CONFIG (JSON file or built-in name): CSV and figures")
    builtin = f"; built-in: {', '.join(pkg.studies)}" if pkg.studies else ""
    study.add_argument("config", metavar="CONFIG", help=f"study configuration: a JSON file{builtin}")
    study.add_argument("--workers", type=int, default=None, help="worker processes")
    study.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    study.add_argument("--cache-dir", default=None, help="reference cache (default OUT/.cache/reparam-lab)")
    common(study, "replace every cell's samples per trial (n or spp)", None, seed=None)
    study.set_defaults(func=_study)
    return parser


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
        args = _parser(package).parse_args(argv)
        _check_counts(args)
        return args.func(package, args)
    except _UsageError as e:
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
