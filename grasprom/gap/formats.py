"""File formats of the diagnosis outputs (names and version of ``report.json`` and
``augmented_model.json``) and the conversion of a report to plain JSON values."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

FORMAT_REPORT = "grasprom-diagnosis"
FORMAT_AUGMENTED = "grasprom-augmented-model"
FORMAT_VERSION = 1


def jsonable(o: Any) -> Any:
    """``o`` with string keys, lists for tuples, Python scalars and None for non-finite floats."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [jsonable(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o
