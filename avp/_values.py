"""Value equality for the frozen dataclasses that hold arrays (:class:`avp.State`,
:class:`avp.PerchTarget` and its kin): the dataclass-generated ``==`` compares field tuples, which
for NumPy arrays raises ("the truth value of an array is ambiguous"), and its hash fails on
arrays. Two objects are equal when they are of the same type and every field is equal (arrays
element-wise, ``np.array_equal``); the hash agrees with that (``-0.0`` and ``0.0`` hash alike)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


def _key(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return (value.shape, tuple(value.ravel().tolist()))
    return value


def fields_equal(self: Any, other: object) -> bool:
    """``self == other``: the same type and equal fields (arrays element-wise)."""
    fields = dataclasses.fields(self)
    if type(other) is not type(self):
        return NotImplemented  # type: ignore[no-any-return]
    for f in fields:
        a, b = getattr(self, f.name), getattr(other, f.name)
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            if not np.array_equal(a, b):
                return False
        elif a != b:
            return False
    return True


def fields_hash(self: Any) -> int:
    """A hash consistent with :func:`fields_equal`."""
    return hash((type(self).__name__, *(_key(getattr(self, f.name)) for f in dataclasses.fields(self))))
