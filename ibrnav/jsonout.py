"""Strict JSON for every `ibrnav` command that prints or writes JSON (RFC 8259: no NaN,
Infinity or -Infinity, which Python's `json` writes by default and strict parsers reject).
A value that is not a finite number (a query that was not localised has no error; a
renderer that covered nothing has no PSNR) is written as null; the record that holds it
says why (a `reason` or `success: false` beside it). NumPy scalars and arrays are written as
the numbers and lists they hold."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np


def strict(value: Any) -> Any:
    """value with every non-finite float replaced by None, recursively through dicts, lists,
    tuples and NumPy arrays; NumPy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k) if not isinstance(k, str) else k: strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict(v) for v in value]
    if isinstance(value, np.ndarray):
        return strict(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value: Any, indent: int | None = 2) -> str:
    """Strict JSON text of value (non-finite numbers as null)."""
    return json.dumps(strict(value), indent=indent, allow_nan=False)


def write(path: str | Path, value: Any, indent: int | None = 2) -> str:
    """Write value as strict JSON (and a final newline) to path; returns the text."""
    text = dumps(value, indent)
    Path(path).write_text(text + "\n")
    return text
