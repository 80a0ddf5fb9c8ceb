"""``usvdrake bench NAME [ARGS...]``: run the repository's bench/NAME.py as ``__main__`` (each
prints one JSON object); ``usvdrake bench --list`` (or no NAME) lists them with their first
docstring line."""

import argparse
import ast
import runpy
import sys
from pathlib import Path

from usvdrake.errors import ConfigError

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"


def benchmarks() -> dict[str, str]:
    """name → first docstring line of every bench/*.py (without running it)."""
    out = {}
    for path in sorted(BENCH_DIR.glob("*.py")) if BENCH_DIR.is_dir() else []:
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        first = doc.strip().splitlines()[0] if doc.strip() else ""
        out[path.stem] = first.removeprefix("Benchmark: ")
    return out


def _listing() -> str:
    names = benchmarks()
    if not names:
        return (
            "no bench/ folder beside the package: the benchmarks run from a source checkout "
            "of usvdrake (git clone, then make bench or usvdrake bench NAME)"
        )
    width = max(len(n) for n in names)
    return "benchmarks (usvdrake bench NAME [ARGS]; NAME --help for its options):\n" + "\n".join(
        f"  {name:<{width}}  {line}" for name, line in names.items()
    )


def add_arguments(b) -> None:
    b.description = _listing()
    b.formatter_class = argparse.RawDescriptionHelpFormatter
    b.add_argument("name", nargs="?", default=None, help="a benchmark (listed above)")
    b.add_argument("args", nargs=argparse.REMAINDER, help="passed to the benchmark")


def run(args) -> int:
    if args.name is None:
        print(_listing())
        return 0
    path = BENCH_DIR / f"{args.name}.py"
    names = benchmarks()
    if args.name not in names or not path.is_file():
        expected = "one of " + ", ".join(names) if names else "a benchmark (no bench/ folder)"
        raise ConfigError("bench", "name", expected, repr(args.name))
    sys.argv = [str(path), *args.args]
    runpy.run_path(str(path), run_name="__main__")
    return 0
