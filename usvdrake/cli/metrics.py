"""``usvdrake metrics LOG``: measure a recorded mission again from its ``log.mcap`` (the same
function the live run used), print the numbers, optionally write them as JSON."""

import json
from pathlib import Path

from usvdrake.cli._format import table
from usvdrake.errors import ConfigError
from usvdrake.run.measure import metrics_from_log


def add_arguments(m) -> None:
    m.add_argument("log", help="a mission log (log.mcap) or the run folder holding it")
    m.add_argument("--out", default=None, help="write metrics.json here (a file or a folder)")


def run(args) -> int:
    log = Path(args.log)
    if log.is_dir():
        log = log / "log.mcap"
    if not log.is_file():
        raise ConfigError(str(args.log), "", "a mission log (log.mcap or its run folder)", "none")
    try:
        metrics = metrics_from_log(log)
    except ValueError as e:
        raise ConfigError(str(log), "", "a finished usvdrake mission log", str(e)) from None
    print(f"usvdrake metrics {log}: scenario {metrics['scenario']}, replayed from the log")
    print("\n".join(table(metrics)))
    if args.out:
        out = Path(args.out)
        path = out / "metrics.json" if out.suffix != ".json" else out
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(metrics, indent=2) + "\n")
        print(f"  metrics.json  {path}")
    return 0
