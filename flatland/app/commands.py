"""The verbs of the command line (:mod:`flatland.app.cli`): ``demo``, ``render``, ``gradient``, ``study``.

Each verb is a function ``(package, args) -> exit status`` that the parser of
:mod:`flatland.app.cli` attaches to its subcommand; what a verb does is described
there. Figures are drawn by the package's writers (:meth:`Package.plot
<flatland.app.cli.Package.plot>`), with the scene's sketch on the left when the package
has one (:attr:`Package.sketch <flatland.app.cli.Package>`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flatland.app.table import error_table, format_exact, format_interval, format_level, method_label
from flatland.core.stats import LEVEL, family_quantile, normal_quantile
from flatland.core.validate import ValidationError, check_positive

if TYPE_CHECKING:
    from flatland.app.cli import Package

__all__ = [
    "DEMO_METHODS",
    "PANEL_TITLES",
    "REFERENCE_GROWTH",
    "UsageError",
    "verb_demo",
    "verb_gradient",
    "verb_render",
    "verb_study",
]

REFERENCE_GROWTH = 4
"""The demo's reference grows to at most this many times its first sample count (a warning beyond)."""
DEMO_METHODS = ("naive", "boundary", "reparam", "finite_difference")
"""Panel columns after the primal, in order (those the package has)."""
PANEL_TITLES = {"finite_difference": "finite differences"}


class UsageError(Exception):
    """A mistake in the arguments (an argparse error or a missing one), reported as one line."""


# ---------------------------------------------------------------------------------------------- helpers
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


def _progress(args: argparse.Namespace) -> bool | None:
    """``--quiet``: no progress bar; else one when stderr is a terminal (:mod:`flatland.core.progress`)."""
    return False if getattr(args, "quiet", False) else None


def _film(args: argparse.Namespace) -> dict[str, Any]:
    """``film=`` when ``--film`` was given (only packages with films have the option)."""
    return {} if getattr(args, "film", None) is None else {"film": args.film}


def _scheduler(args: argparse.Namespace) -> dict[str, Any]:
    """``scheduler=`` when ``--scheduler`` was given (only packages with ``Package.cluster`` have it)."""
    return {} if getattr(args, "scheduler", None) is None else {"scheduler": args.scheduler}


def _depth(args: argparse.Namespace) -> dict[str, Any]:
    """``max_depth=`` when ``--max-depth`` was given (default: the renderers' own, 1)."""
    return {} if getattr(args, "max_depth", None) is None else {"max_depth": args.max_depth}


def _reference_needed(gradients: Mapping[str, Any], reference: Any, ref_spp: int) -> int | None:
    """Reference spp that makes its film-sum stderr 1/4 of the smallest unbiased method's (x 1.25
    for the scatter of the estimated errors), or None if it already is."""
    from flatland.core.bias import REFERENCE_RATIO, reference_spp_needed

    ref_se = reference.film_sum().stderr
    ratio = _reference_ratio(gradients, reference)
    if ratio <= REFERENCE_RATIO:
        return None
    return reference_spp_needed(ref_spp, ref_se, ref_se / ratio)


def _reference_ratio(gradients: Mapping[str, Any], reference: Any) -> float:
    """Reference film-sum stderr / the smallest among the methods the table does not flag (a flag
    already counts the reference's noise in its interval); 0 when there is none. The film sums'
    standard errors come from the per-batch sums (:meth:`~flatland.core.image.GradientImage.film_sum`)."""
    from flatland.core.bias import error_interval

    ref = reference.film_sum()
    q = family_quantile(max(len(gradients), 1))  # the error table's intervals
    judged = []
    for g in gradients.values():
        s = g.film_sum()
        if not error_interval(s.total, ref.total, s.stderr, ref.stderr, q).biased and s.stderr > 0.0:
            judged.append(s.stderr)
    return ref.stderr / min(judged) if judged else 0.0


def _sketch(pkg: Package, scene: Any, param: str | None = None) -> dict[str, Any]:
    """``{"sketch": draw}`` for a figure writer, drawing ``scene`` (and what ``param`` moves) into an
    Axes, when the package sketches its scenes; ``{}`` when it does not."""
    if pkg.sketch is None:
        return {}
    return {"sketch": lambda ax: pkg.sketch(ax, scene, param)}


def _film_sum(g: Any) -> str:
    """$Σ_j dI_j/dθ$ and its :data:`~flatland.core.stats.LEVEL` interval (standard error from the
    per-batch sums: the pixels may be correlated)."""
    s = g.film_sum()
    if not s.stderr > 0.0:
        return format_exact(s.total)
    half = normal_quantile(LEVEL) * s.stderr
    return f"{format_interval(s.total, s.total - half, s.total + half)} ({format_level(LEVEL)} interval)"


# ------------------------------------------------------------------------------------------------ verbs
def verb_demo(pkg: Package, args: argparse.Namespace) -> int:
    """``demo``: the method panel of the package's default scene and the error table against a reference."""
    from flatland.core.bias import REFERENCE_RATIO

    spp = args.spp or pkg.demo_spp
    seed = args.seed
    scene = _load_scene(pkg, pkg.demo_scene)
    table = pkg.methods
    methods = list(pkg.demo_methods or [m for m in DEMO_METHODS if m in table.names])
    reference_method = (
        pkg.demo_reference
        or pkg.reference_method
        or ("boundary" if "boundary" in table.names else "finite_difference")
    )
    out = Path(args.out)

    progress = _progress(args)
    start = time.perf_counter()
    primal = pkg.render(scene, spp=spp, seed=seed, progress=progress)
    gradients, seconds = {}, {}
    for method in methods:
        t0 = time.perf_counter()
        gradients[method] = pkg.render_gradient(
            scene, pkg.demo_param, method=method, spp=spp, seed=seed, progress=progress
        )
        seconds[method] = time.perf_counter() - t0
    ref_spp = pkg.reference_factor * spp
    ref_options = dict(pkg.reference_options)
    ref_label = method_label(reference_method, ref_options.items())

    def reference_at(count: int) -> Any:
        return pkg.render_gradient(
            scene, pkg.demo_param, method=reference_method, spp=count, seed=seed + 1, progress=progress,
            **ref_options,
        )  # fmt: skip

    reference, cap = reference_at(ref_spp), REFERENCE_GROWTH * ref_spp
    for _ in range(2):  # the reference must be 4 × more precise than the methods it judges
        needed = _reference_needed(gradients, reference, ref_spp)
        if needed is None or ref_spp >= cap:
            break
        ref_spp = min(needed, cap)  # at most REFERENCE_GROWTH × its first count: else a warning
        reference = reference_at(ref_spp)
    columns = {PANEL_TITLES.get(m, m): g for m, g in gradients.items()}
    title = f"{pkg.demo_scene}: d/d {pkg.demo_param}, {spp} spp"
    sketch = _sketch(pkg, scene, pkg.demo_param)
    panel = pkg.plot("panel")(primal, columns, out / "demo_panel.png", title=title, **sketch)
    ratio = _reference_ratio(gradients, reference)
    met = ratio <= REFERENCE_RATIO
    title = (
        f"{pkg.name} demo: scene {pkg.demo_scene!r}, parameter {pkg.demo_param!r}, {spp} spp, seed {seed}\n"
        f"reference: {ref_label} at {ref_spp} spp, seed {seed + 1}: Σ dI/dθ = {_film_sum(reference)}\n"
        f"reference noise: its se / the smallest unbiased method's se = {ratio:.2f}"
        f" (required <= {REFERENCE_RATIO:g}{'' if met else ': NOT MET, see the warning'})"
    )
    print(error_table(gradients, seconds, reference, title))
    if not met:
        print(
            f"warning: the demo's reference is noisier than required ({ratio:.2f} > {REFERENCE_RATIO:g} ×"
            f" the smallest unbiased method's standard error) at {ref_spp} spp, the most it may grow to;"
            " its noise is counted in every interval and flag, but adds to the relative errors",
            file=sys.stderr,
        )
    print(f"\nwrote {panel}  ({time.perf_counter() - start:.1f} s)")
    for section in pkg.demo_sections:
        print()
        print(section(args))
    return 0


def verb_render(pkg: Package, args: argparse.Namespace) -> int:
    """``render SCENE``: the image as PNG and ``.npy``."""
    scene = _load_scene(pkg, args.scene)
    image = pkg.render(
        scene, spp=args.spp, seed=args.seed, batches=args.batches, progress=_progress(args),
        **_film(args), **_scheduler(args), **_depth(args),
    )  # fmt: skip
    name = _stem(args.scene)
    out = Path(args.out)
    png = pkg.plot("image")(
        image, out / f"{name}.png", title=f"{name}, {args.spp} spp", **_sketch(pkg, scene)
    )
    npy = _save_fields(out / f"{name}.npy", value=image.value, value_stderr=image.stderr)
    print(f"wrote {png} and {npy} (fields value, value_stderr; film shape {image.shape})")
    return 0


def verb_gradient(pkg: Package, args: argparse.Namespace) -> int:
    """``gradient SCENE --param P --method M``: the derivative image as PNG and ``.npy``."""
    scene = _load_scene(pkg, args.scene)
    if args.param is None:
        names = ", ".join(pkg.parameter_names(scene))
        raise UsageError(f"gradient: --param is required; parameters of {scene.name!r}: {names}")
    g = pkg.render_gradient(
        scene, args.param, method=args.method, spp=args.spp, seed=args.seed, batches=args.batches,
        progress=_progress(args), **_film(args), **_scheduler(args), **_options(args), **_depth(args),
    )  # fmt: skip
    name = f"{_stem(args.scene)}_{args.param}_{args.method}"  # parameter names contain dots: no with_suffix
    out = Path(args.out)
    title = f"{_stem(args.scene)}: d/d {args.param}, {args.method}, {args.spp} spp"
    png = pkg.plot("gradient")(g, out / f"{name}.png", title=title, **_sketch(pkg, scene, args.param))
    npy = _save_fields(
        out / f"{name}.npy",
        value=g.value,
        value_stderr=g.value_stderr,
        derivative=g.derivative,
        derivative_stderr=g.derivative_stderr,
    )
    print(f"Σ dI/dθ over the film = {_film_sum(g)}")
    print(f"wrote {png} and {npy} (fields value, value_stderr, derivative, derivative_stderr)")
    return 0


def verb_study(pkg: Package, args: argparse.Namespace) -> int:
    """``study CONFIG``: run a study; CSV and figures in ``--out``."""
    from flatland.app.study import run_study
    from flatland.app.study_config import load_config
    from flatland.app.study_reading import reading

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
        progress=_progress(args),
    )
    csv_path = result.to_csv(out / f"{config.name}.csv")
    figures = pkg.plot("study")(result, out)
    print(result.table())
    print("\n" + reading(result))
    print(f"\nwrote {csv_path}" + "".join(f", {f}" for f in figures) + f"  ({result.seconds:.1f} s)")
    return 0
