"""Scenarios as the diagram builders accept them: values checked, and the chosen variants'
own checks passed (:func:`usvdrake.diagrams.variants.check_variants`)."""

from pathlib import Path

from usvdrake.diagrams.variants import check_variants
from usvdrake.scenario import Scenario, override, read_scenario, validate_scenario


def check_scenario(s: Scenario, file: str | Path = "scenario") -> Scenario:
    """Every check of ``s``: values (:func:`~usvdrake.scenario.validate_scenario`) and what its
    estimator, controller and SLAM method need. Returns ``s`` unchanged."""
    return check_variants(validate_scenario(s, file), str(file))


def load_scenario(name_or_path: str | Path | None = None) -> Scenario:
    """Load a shipped scenario by name, or a scenario YAML file; None gives the demo scenario.
    A bad file stops with one line (:class:`~usvdrake.errors.ConfigError`)."""
    s = read_scenario(name_or_path)
    return check_variants(s, s.name if name_or_path is None else str(name_or_path))


def with_overrides(s: Scenario, duration: float | None = None, seed: int | None = None) -> Scenario:
    """A checked copy of ``s`` with command-line overrides (``s`` itself is never modified)."""
    return check_variants(override(s, duration, seed), f"{s.name} (command line)")
