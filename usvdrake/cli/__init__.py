"""The ``usvdrake`` command: ``run`` a scenario, ``campaign`` it over random days, ``bench`` a
benchmark, ``identify`` ξ, run SLAM offline (``slam2d``, ``slam3d``, ``slam3d-ablation``), meet
ship traffic (``encounter``, ``encounters``).

One module per subcommand (``usvdrake.cli.<module>``), each with ``add_arguments(parser)`` and
``run(args) -> int``. This package imports only the standard library, :mod:`usvdrake.errors` and
:mod:`usvdrake.run.interrupt`: :func:`main` imports the one command module it dispatches to,
so ``usvdrake --help`` does not pull in Drake, gtsam or scipy.
"""

import argparse
import importlib
import signal
import sys

from usvdrake.errors import ConfigError
from usvdrake.run.interrupt import stop_on_signals

# (command, module in usvdrake.cli, one-line help)
COMMANDS: tuple[tuple[str, str, str], ...] = (
    ("run", "run", "simulate a scenario and write metrics, replay and report"),
    (
        "hil",
        "hil",
        "hardware-in-the-loop: the hardware diagram against emulated devices in real time",
    ),
    ("campaign", "campaign", "Monte Carlo: run a scenario over many random days (Dask)"),
    ("bench", "bench", "run bench/NAME.py (prints one JSON object)"),
    ("identify", "identify", "fit ξ = [m11 m22 m33 Xu Yv Nr] to a log (Roboat II eq. 9)"),
    ("identify-data", "identify_data", "write a synthetic identification log (Roboat II §VI-B)"),
    (
        "slam2d",
        "slam2d",
        "2D graph SLAM (Pham et al.) on recorded scans (scan only unless --odometry)",
    ),
    ("slam3d", "slam3d", "lidar-IMU-GPS factor-graph SLAM (Roboat II §V) on a recording"),
    (
        "slam3d-ablation",
        "slam3d_ablation",
        "Roboat II §VI-A ablation: lidar / + GPS / + GPS + loop on a recording or a scenario",
    ),
    ("analyze", "analyze", "analyses of a scenario's closed loop"),
    ("metrics", "metrics", "measure a recorded mission again from its log.mcap"),
    ("encounter", "encounter", "one DNV traffic situation: own ship with SB-MPC COLAV on AIS"),
    (
        "encounters",
        "encounters",
        "a set of traffic situations on Dask (default: DNV's 40 standard encounters)",
    ),
)
_MODULES = {name: module for name, module, _ in COMMANDS}


def _command_module(command: str):
    """The module ``usvdrake.cli.<module>`` of ``command`` (imported now: Drake etc. with it)."""
    return importlib.import_module(f"{__name__}.{_MODULES[command]}")


class _OneLineParser(argparse.ArgumentParser):
    """A bad argument is one line on stderr and exit 2, like every other refusal (argparse
    prints the whole usage first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def make_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``usvdrake`` parser: every command with its help only, and ``command``'s (if given)
    full arguments, added by its module's ``add_arguments`` (which imports that module)."""
    p = _OneLineParser(prog="usvdrake", description="Autonomous surface vessels as Drake diagrams.")
    sub = p.add_subparsers(dest="command", required=True)
    for name, _, help_text in COMMANDS:
        parser = sub.add_parser(name, help=help_text)
        if name == command:
            _command_module(name).add_arguments(parser)
    return p


def _find_command(argv: list[str]) -> str | None:
    """The command named in ``argv``: its first non-option item, if that is a command."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in _MODULES else None


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    command = _find_command(argv)
    args = make_parser(command).parse_args(argv)
    try:
        with stop_on_signals():  # SIGINT/SIGTERM: simulations stop and write their outputs
            return _command_module(args.command).run(args)
    except ConfigError as e:
        print(f"usvdrake: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # a second Ctrl-C, or a command that cannot stop cleanly
        print(f"usvdrake {args.command}: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT
