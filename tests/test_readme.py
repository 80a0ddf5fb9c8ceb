"""Every command the README shows runs as written (``make`` aside: CI runs ``make test`` itself,
and ``make demo`` is ``usvdrake run --out out/demo``, run first here). Commands run in order in
one scratch folder, so a command that reads what an earlier one wrote finds it; simulated
durations are capped at 10 s and campaigns at 2 runs to keep the suite short."""

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
CAPS = {"--duration": 10.0, "--runs": 2, "--samples": 500, "--trials": 2}


def readme_commands() -> list[str]:
    """The ``usvdrake`` command lines inside the README's ```bash blocks (plain blocks show
    output, not commands)."""
    commands, fenced = [], False
    for line in README.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced and line.strip() in ("```bash", "```sh")
            continue
        text = line.split("#", 1)[0].strip()
        if fenced and re.match(r"^(\.venv/bin/)?usvdrake\s", text):
            commands.append(text)
    return commands


def _capped(argv: list[str]) -> list[str]:
    out = list(argv)
    for i, arg in enumerate(out[:-1]):
        if arg in CAPS:
            value = float(out[i + 1])
            out[i + 1] = f"{min(value, CAPS[arg]):g}"
    return out


def test_the_readme_shows_commands():
    assert len(readme_commands()) >= 8


@pytest.mark.slow
def test_every_readme_command_runs_as_written(tmp_path):
    # the fixtures a fresh clone has, where the README's commands look for them
    shutil.copytree(ROOT / "tests" / "data", tmp_path / "tests" / "data")
    usvdrake = [sys.executable, "-m", "usvdrake.cli"]
    setup = [*usvdrake, "run", "--out", "out/demo", "--duration", "10", "--quiet"]  # make demo
    assert subprocess.run(setup, cwd=tmp_path, capture_output=True).returncode == 0
    for command in readme_commands():
        argv = shlex.split(command)[1:]  # without the program: `usvdrake` or `.venv/bin/usvdrake`
        if argv[0] in ("run", "campaign", "hil", "slam2d", "slam3d", "slam3d-ablation"):
            argv.append("--quiet")
        done = subprocess.run(
            [*usvdrake, *_capped(argv)],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
            timeout=900,
        )
        assert done.returncode == 0, f"{command}\n{done.stdout[-1500:]}\n{done.stderr[-2500:]}"
        assert "Traceback" not in done.stderr, f"{command}\n{done.stderr[-2500:]}"
