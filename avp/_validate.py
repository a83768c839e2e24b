"""Input validation shared by the public dataclasses: read-only float arrays, finiteness,
shapes, rotations. Every failure is a :class:`~avp.errors.ConfigError` naming the field."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import numbers
from collections.abc import Callable, Mapping
from decimal import Decimal
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from .errors import ConfigError

_Cls = TypeVar("_Cls", bound=type)

ORTHONORMAL_TOL = 1e-6
"""Tolerance on ``|R^T R - I|`` (max entry) and ``|det R - 1|`` for rotation inputs."""


def float_array(field: str, value: Any, expected: str) -> npt.NDArray[np.float64]:
    """``np.array(value, dtype=float)``, or a :class:`ConfigError` on ``field``: "expected
    ``expected``" when ``value`` holds no numbers, and its own message for an int beyond the
    float range (NumPy's ``OverflowError``)."""
    try:
        return np.array(value, dtype=float)
    except OverflowError as exc:
        raise ConfigError(field, "has a number beyond the float range; pass finite values") from exc
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"expected {expected}, got {value!r}") from exc


def finite_times(field: str, t: Any) -> tuple[npt.NDArray[np.float64], float, float]:
    """``t`` (a number or an array of them, s) as a float array, with its least and greatest
    value; a :class:`ConfigError` on ``field`` when it holds no numbers (strings, ``None``, booleans,
    complex numbers, dates) or NaN or inf."""
    if isinstance(t, (list, tuple)) and holds_booleans(t):
        raise ConfigError(field, f"expected times in s (numbers), got booleans in {t!r}")  # NumPy reads 1.0
    try:
        raw = t if isinstance(t, np.ndarray) else np.asarray(t)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(field, f"expected times in s, got {t!r}") from exc
    if raw.dtype.kind == "O" and not any(isinstance(x, (str, bytes, bool, np.bool_)) or x is None
                                         for x in raw.ravel().tolist()):
        try:  # numbers held as objects (Fraction, Decimal): their float values
            raw = raw.astype(float)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ConfigError(field, f"expected times in s (numbers), got {t!r}") from exc
    if raw.dtype.kind not in "fiu":  # strings, None, booleans: no time
        raise ConfigError(field, f"expected times in s (numbers), got {t!r}")
    arr = raw.astype(float, copy=False)
    lo = hi = math.nan
    if arr.size:
        lo, hi = float(arr.min()), float(arr.max())  # NaN propagates to both
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ConfigError(field, "contains NaN or inf")
    return arr, lo, hi


def frozen_array(field: str, value: Any, shape: tuple[int, ...]) -> npt.NDArray[np.float64]:
    """A finite float64 copy of ``value`` with exactly ``shape``, marked read-only (booleans are
    refused: ``True`` is no coordinate)."""
    if holds_booleans(value):
        raise ConfigError(field, f"expected numbers of shape {shape}, got booleans {value!r}")
    arr = float_array(field, value, f"numbers of shape {shape}")
    if arr.shape != shape:
        if arr.size == math.prod(shape) and arr.ndim <= 1 and len(shape) == 1:
            arr = arr.reshape(shape)
        else:
            raise ConfigError(field, f"expected shape {shape}, got {arr.shape}")
    if not _all_finite(arr):
        raise ConfigError(field, "contains NaN or inf; pass finite values")
    arr.setflags(write=False)
    return arr


def _all_finite(arr: npt.NDArray[np.float64]) -> bool:
    """Every entry of a float array is finite (a Python loop for the small arrays of the
    planner's inputs, where it is several times cheaper than NumPy's dispatch)."""
    if arr.size <= 16:
        return all(map(math.isfinite, arr.ravel().tolist()))
    return bool(np.isfinite(arr).all())


def vector(field: str, value: Any, size: int = 3) -> npt.NDArray[np.float64]:
    """``value`` as a finite (writable) float vector of length ``size``; a scalar is broadcast."""
    arr = float_array(field, value, f"{size} numbers")
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ConfigError(field, f"expected shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(field, "contains NaN or inf; pass finite values")
    return arr


_NOT_QUANTITIES = (bool, np.bool_, str, bytes)
"""Types a float field refuses though ``float()`` takes them: a bool (Python's or NumPy's) is not
a quantity, and a string that parses would be stored as given by a caller that does not keep the
result."""


def holds_booleans(value: Any) -> bool:
    """Whether ``value`` is a boolean, an array of them, or a (nested) list or tuple holding one:
    NumPy reads ``True`` as 1.0, which is no coordinate, time or duration."""
    if isinstance(value, (list, tuple)):
        return any(holds_booleans(x) for x in value)
    return isinstance(value, (bool, np.bool_)) or _is_bool_array(value)


def _is_bool_array(value: Any) -> bool:
    """A NumPy array of booleans (``float()`` takes a 0-d one as 0.0 or 1.0)."""
    return isinstance(value, np.ndarray) and value.dtype.kind == "b"


LIMITS = {"position": (1e6, "m"), "velocity": (1e3, "m/s"), "acceleration": (1e4, "m/s^2"),
          "jerk": (1e6, "m/s^3"), "yaw": (1e6, "rad"), "yaw_rate": (1e3, "rad/s"), "time": (1e10, "s"),
          "duration": (1e4, "s"), "distance": (1e6, "m")}
"""Magnitudes beyond which a state or a pad is not a flight (a 1000 km position, 1 km/s, or a
time past 1e10 s, where float64 times resolve 2e-6 s; a plan's durations are exact at any
clock, :class:`avp.State`):
refused by :func:`within`, since past them the planner's arithmetic overflows or rounds instead
of failing clearly."""


def within(field: str, value: Any, kind: str) -> None:
    """Raise :class:`ConfigError` when ``max |value|`` exceeds :data:`LIMITS` ``[kind]``."""
    limit, unit = LIMITS[kind]
    if isinstance(value, float):
        size = abs(value)
    elif type(value) is np.ndarray and 0 < value.size <= 16 and value.dtype == np.float64:
        entries = value.ravel().tolist()
        # NaN propagates through np.max (no refusal here: finiteness is checked apart)
        size = math.nan if any(map(math.isnan, entries)) else max(map(abs, entries))
    else:
        size = float(np.max(np.abs(value)))
    if size > limit:
        raise ConfigError(field, f"has magnitude {size:.3g} {unit}, beyond {limit:g} {unit}: not a physical "
                          f"{kind.replace('_', ' ')} of a flight (check the units and the frame)")


def integer(field: str, value: Any, lo: int, hi: int | None = None, hint: str = "") -> int:
    """``value`` as an ``int`` in ``[lo, hi]`` (``hi`` ``None``: no upper end); a bool, a float
    or a string is refused. ``hint`` is appended to the message (what the range means)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < lo or (hi is not None and value > hi):
        span = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ConfigError(field, f"must be an integer {span}{' ' + hint if hint else ''}, got {value!r}")
    return int(value)


def finite_float(field: str, value: Any) -> float:
    """``value`` as a finite float (a bool or a string is refused, :data:`_NOT_QUANTITIES`)."""
    if isinstance(value, _NOT_QUANTITIES) or _is_bool_array(value):
        raise ConfigError(field, f"expected a number, got {value!r}")
    try:
        out = float(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(field, f"expected a finite number, got {value!r}") from exc
    if not math.isfinite(out):
        raise ConfigError(field, f"must be finite, got {out}")
    return out


def nonnegative_float(field: str, value: Any) -> float:
    """``value`` as a finite float >= 0 (a bool or a string is refused, as in :func:`finite_float`)."""
    out = finite_float(field, value)
    if out < 0.0:
        raise ConfigError(field, f"must be >= 0, got {out}")
    return out


def positive_float(field: str, value: Any, *, allow_inf: bool = False) -> float:
    """``value`` as a float > 0 (``inf`` allowed when ``allow_inf``, meaning "no limit"; a bool or
    a string is refused, as in :func:`finite_float`)."""
    if isinstance(value, _NOT_QUANTITIES) or _is_bool_array(value):
        raise ConfigError(field, f"expected a positive number, got {value!r}")
    try:
        out = float(value)
    except OverflowError as exc:
        raise ConfigError(field, f"must be positive{' (or inf for no limit)' if allow_inf else ''} and finite, "
                                 "got a number beyond the float range") from exc
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"expected a positive number, got {value!r}") from exc
    if math.isnan(out) or out <= 0.0 or (math.isinf(out) and not allow_inf):
        raise ConfigError(field, f"must be positive{' (or inf for no limit)' if allow_inf else ''} and finite, got {out}")
    return out


def boolean(field: str, value: Any) -> bool:
    """``value`` as ``True`` or ``False`` (a NumPy boolean too); anything else, whose truth
    value would silently switch the option, is refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(field, f"expected True or False, got {value!r}")
    return bool(value)


def flags(prefix: str, obj: Any) -> None:
    """Every field of the dataclass ``obj`` annotated ``bool`` holds ``True`` or ``False`` (a
    NumPy boolean is stored as Python's): a string such as ``"no"``, a number or ``None`` is
    refused, since its truth value would silently switch the option. A field annotated
    ``bool | None`` may also hold ``None`` (not known). ``obj`` is frozen or not."""
    for f in dataclasses.fields(obj):
        optional = f.type == "bool | None"
        if f.type not in ("bool", bool) and not optional:
            continue
        value = getattr(obj, f.name)
        if isinstance(value, np.bool_):
            object.__setattr__(obj, f.name, bool(value))
        elif not isinstance(value, bool) and not (optional and value is None):
            allowed = "True, False or None" if optional else "True or False"
            raise ConfigError(f"{prefix}.{f.name}", f"expected {allowed}, got {value!r} ({type(value).__name__})")


_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


def rotation(field: str, value: Any) -> npt.NDArray[np.float64]:
    """A proper rotation matrix (orthonormal, det +1), read-only."""
    R = frozen_array(field, value, (3, 3))
    err = max(map(abs, (R.T @ R - _EYE3).ravel().tolist()))
    if err > ORTHONORMAL_TOL:
        raise ConfigError(field, f"is not orthonormal (max |R^T R - I| = {err:.2e}); pass a rotation matrix")
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = R.tolist()
    det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    if abs(det - 1.0) > ORTHONORMAL_TOL:
        raise ConfigError(field, f"has determinant {det:.3f}; a rotation needs +1 (right-handed frame)")
    return R


def unit_vector(field: str, value: Any, zero: str = "must be a nonzero vector") -> npt.NDArray[np.float64]:
    """``value`` normalised to unit length; rejects (near) zero vectors (message ``zero``)."""
    v = np.array(frozen_array(field, value, (3,)))
    scale = max(map(abs, v.tolist()))
    if scale > 1e150:  # |v| would overflow: scaled first
        v = v / scale
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise ConfigError(field, zero)
    return v / n


def sequence(field: str, value: Any, what: str, single: tuple[type, ...] = ()) -> tuple[Any, ...]:
    """``value`` as a tuple of its items; a string, a mapping, a non-iterable or one item of a
    ``single`` type (a lone element where a sequence of them belongs) is refused, the message
    saying it must be a sequence of ``what``."""
    if isinstance(value, (str, bytes, Mapping, *single)) or not hasattr(value, "__iter__"):
        wrap = f"; wrap a single one: ({single[0].__name__}(...),)" if isinstance(value, single) else ""
        raise ConfigError(field, f"must be a sequence of {what}, got {value!r}{wrap}")
    try:
        return tuple(value)
    except TypeError as exc:  # an __iter__ that refuses (a 0-d NumPy array)
        raise ConfigError(field, f"must be a sequence of {what}, got {value!r}") from exc


def keywords(prefix: str, cls: type, names: tuple[str, ...], kwargs: Mapping[str, Any], also: tuple[str, ...] = ()) -> None:
    """Refuse a keyword of ``kwargs`` that is not among ``names`` (the settings of ``cls``; a
    constructor's own arguments ``also``): a :class:`ConfigError` on ``prefix.<keyword>`` listing
    them (Python's own error is a ``TypeError``, outside the library's one hierarchy)."""
    unknown = next((k for k in kwargs if k not in names and k not in also), None)
    if unknown is not None:
        own = f" (and the constructor's {', '.join(also)})" if also else ""
        raise ConfigError(f"{prefix}.{unknown}", f"is not a {cls.__name__} setting; use one of "
                                                 f"{', '.join(map(repr, names))}{own}")


_FLOAT_TYPES = frozenset({float, "float", "float | None", "Optional[float]"})
"""Annotations of the dataclass fields that hold one real number (``from __future__ import
annotations`` keeps them as strings)."""


def _as_float(value: Any) -> Any:
    """A real number that is not a Python float (``Decimal``, ``Fraction``, a NumPy scalar or
    0-d array) as the float it stands for; anything else (``None``, a bool, a string, an array,
    a float already, an int beyond the float range) unchanged, for the field's validator to take
    or refuse."""
    if type(value) is float or value is None or isinstance(value, (bool, np.bool_)):
        return value
    if isinstance(value, np.ndarray):
        if value.ndim != 0 or value.dtype.kind not in "iuf":
            return value
        value = value[()]
    if isinstance(value, (numbers.Real, Decimal)):
        try:
            return float(value)
        except (OverflowError, ValueError):  # an int beyond the float range, a signalling NaN: refused
            return value
    return value


def typed_keywords(prefix: str) -> Callable[[_Cls], _Cls]:
    """Class decorator (above ``@dataclass``): the constructor refuses a keyword that is not one
    of its parameters (the init fields and any ``InitVar``) with :func:`keywords`, and passes a
    real number that is not a Python float (a ``Decimal``, a ``Fraction``, a NumPy scalar or 0-d
    array) to a ``float`` field as the float it stands for, so the stored settings are plain
    floats the planner's arithmetic takes. Positional arguments are matched to the generated
    constructor's positional parameters (``kw_only`` fields are none; an ``InitVar`` is one), so
    any dataclass layout is read right. A class that is not a dataclass with an ``__init__`` of
    its own is a ``TypeError`` at decoration (a hand-written ``__init__`` is wrapped as it is)."""

    def wrap(cls: _Cls) -> _Cls:
        init = vars(cls).get("__init__")  # the dataclass-generated constructor
        if not dataclasses.is_dataclass(cls) or init is None:
            raise TypeError(f"typed_keywords({prefix!r}): {cls.__name__} must be a dataclass with its own generated "
                            "__init__ (place the decorator above @dataclass)")
        # The constructor's own parameters, not the fields' order: a kw_only field is no positional
        # argument, and an InitVar is a parameter that is no field
        params = list(inspect.signature(init).parameters.values())[1:]  # without self
        names = tuple(p.name for p in params)
        known = frozenset(names)
        types = {f.name: f.type for f in dataclasses.fields(cls) if f.init}
        floats = frozenset(n for n in names if types.get(n) in _FLOAT_TYPES)
        positions = tuple(p.name in floats for p in params if p.kind is p.POSITIONAL_OR_KEYWORD)

        @functools.wraps(init)
        def checked_init(self: Any, *args: Any, **kwargs: Any) -> None:
            if not known.issuperset(kwargs):
                keywords(prefix, cls, names, kwargs)
            if floats:  # a Decimal, a Fraction, a NumPy scalar: stored as the float it stands for
                args = tuple(_as_float(a) if i < len(positions) and positions[i] else a for i, a in enumerate(args))
                kwargs = {k: _as_float(a) if k in floats else a for k, a in kwargs.items()}
            init(self, *args, **kwargs)

        setattr(cls, "__init__", checked_init)  # noqa: B010  # (a method assignment mypy refuses)
        return cls

    return wrap
