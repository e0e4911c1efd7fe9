"""Run every ``benchmarks/bench_*.py`` module and print one table."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import platform
import sys
import time

import benchmarks
from benchmarks import Row


def _format(rows: list[Row]) -> str:
    headers = ("section", "case", "value", "unit", "note")
    cells = [(r.section, r.case, f"{r.value:.4g}", r.unit, r.note) for r in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(headers)]
    line = "  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(cell, widths, strict=True)) for cell in cells]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("--only", help="run only modules whose name contains this string")
    args = parser.parse_args(argv)
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    if args.only:
        names = [n for n in names if args.only in n]
    py = f"{platform.python_implementation()} {platform.python_version()}"
    print(f"# {py}, {os.cpu_count()} cores, {platform.machine()}")
    rows: list[Row] = []
    for name in names:
        start = time.perf_counter()
        module = importlib.import_module(f"benchmarks.{name}")
        rows += module.run()
        print(f"# {name}: {time.perf_counter() - start:.1f} s", file=sys.stderr)
    print(_format(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
