"""Checks of public API arguments: one wording for every function that takes them.

A value of the wrong kind raises ``TypeError`` (``seed=1.5``, ``seed='7'``, ``spp=True``: a bool is
not an integer here, although Python lets it be one); a value of the right kind outside its range
raises ``error`` (``ValueError`` unless the caller names a subclass, e.g. ``AccumulatorError``).
Every message names the argument and the value given. numpy integers and floats are accepted
wherever Python ones are.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np


def _kind(value: object) -> str:
    return f"{type(value).__name__} {value!r}"


def _range(lo: float | None, hi: float | None) -> str:
    if lo is not None and hi is not None:
        return f" in {lo}..{hi}"
    if lo is not None:
        return f" >= {lo}"
    if hi is not None:
        return f" <= {hi}"
    return ""


def is_int(value: object) -> bool:
    """True for a Python or numpy integer; False for a bool (True is not a sample count)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_int(value: object, name: str, *, lo: int | None = None, hi: int | None = None,
              error: type[Exception] = ValueError, note: str = "") -> int:
    """``value`` as an int in [lo, hi] (either bound may be None); ``note`` is added after the range
    in the message (e.g. ``" (-1 = unlimited)"``)."""
    if not is_int(value):
        raise TypeError(f"{name} must be an integer{_range(lo, hi)}{note}, got {_kind(value)}")
    v = int(value)  # type: ignore[arg-type]
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise error(f"{name} must be an integer{_range(lo, hi)}{note}, got {v}")
    return v


def check_optional_int(value: object, name: str, **bounds: Any) -> int | None:
    """None, or ``value`` checked by :func:`check_int`."""
    return None if value is None else check_int(value, name, **bounds)


def check_float(value: object, name: str, *, lo: float | None = None, hi: float | None = None,
                error: type[Exception] = ValueError) -> float:
    """``value`` as a finite float in [lo, hi]; ints are accepted, bools and strings are not."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number{_range(lo, hi)}, got {_kind(value)}")
    v = float(value)
    if not math.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
        raise error(f"{name} must be a finite number{_range(lo, hi)}, got {v}")
    return v


def check_bool(value: object, name: str) -> bool:
    """``value`` as a bool: only True or False (and numpy's) are accepted, not 0, 1 or 'yes'."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {_kind(value)}")
    return bool(value)


def check_optional_bool(value: object, name: str) -> bool | None:
    """None, True or False (``progress=``: None means "decide for me")."""
    if value is None:
        return None
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True, False or None, got {_kind(value)}")
    return bool(value)


def check_choice(value: object, name: str, choices: Iterable[str], *,
                 error: type[Exception] = ValueError) -> str:
    """``value``, one of the strings ``choices``."""
    options = tuple(choices)
    listed = ", ".join(options)
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {listed}, got {_kind(value)}")
    if value not in options:
        raise error(f"unknown {name} {value!r} (choose from {listed})")
    return value
