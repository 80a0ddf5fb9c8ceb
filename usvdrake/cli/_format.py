"""Numbers for people: rounded, with units, and "n/a" where a metric has no value."""


def num(value, spec: str = ".2f", unit: str = "") -> str:
    """``value`` formatted by ``spec`` with ``unit`` appended; "n/a" for None."""
    if value is None:
        return "n/a"
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    return f"{value:{spec}}{unit}"


def table(metrics: dict, width: int | None = None) -> list[str]:
    """One aligned line per metric (floats to 4 significant digits, dicts inline)."""
    width = width or max((len(k) for k in metrics), default=0)
    lines = []
    for key, value in metrics.items():
        if isinstance(value, float):
            text = f"{value:.4g}"
        elif isinstance(value, dict):
            text = ", ".join(f"{k} {v}" for k, v in value.items()) or "none"
        else:
            text = str(value)
        lines.append(f"  {key:<{width}} {text}")
    return lines
