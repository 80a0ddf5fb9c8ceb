"""``jsonable``: any nested result → strict JSON values (for metrics, analyses, campaigns)."""

import numpy as np


def jsonable(obj):
    """dicts (keys as str), lists/tuples and numpy arrays/scalars → plain Python; non-finite
    floats → None (strict JSON has no inf or nan); anything else unchanged."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj
