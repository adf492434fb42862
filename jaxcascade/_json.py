"""Strict JSON for every file and line the package writes: NaN and infinities become
`null` (JSON has no such numbers; a status, message or the schema's docs say why),
NumPy scalars and arrays plain numbers and lists."""

from __future__ import annotations

import json
import math


def strict_json(value, **options) -> str:
    """`value` as strict JSON (module docstring); `options` go to `json.dumps`."""
    return json.dumps(finite_or_null(value), allow_nan=False, **options)


def finite_or_null(value):
    """`value` with every non-finite float replaced by None, NumPy values as Python's."""
    if isinstance(value, dict):
        return {key: finite_or_null(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_null(item) for item in value]
    if hasattr(value, "tolist") and not isinstance(value, str):  # NumPy scalars, arrays
        return finite_or_null(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
