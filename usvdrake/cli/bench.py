"""``usvdrake bench NAME [ARGS...]``: run the repository's bench/NAME.py as ``__main__``."""

import argparse
import runpy
import sys
from pathlib import Path

from usvdrake.errors import ConfigError

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"


def add_arguments(b) -> None:
    b.add_argument("name")
    b.add_argument("args", nargs=argparse.REMAINDER)


def run(args) -> int:
    path = BENCH_DIR / f"{args.name}.py"
    if not path.is_file():
        names = sorted(p.stem for p in BENCH_DIR.glob("*.py")) if BENCH_DIR.is_dir() else []
        raise ConfigError(
            "bench", "name", "one of " + (", ".join(names) or "(no bench/ folder)"), repr(args.name)
        )
    sys.argv = [str(path), *args.args]
    runpy.run_path(str(path), run_name="__main__")
    return 0
