"""Piecewise-polynomial trajectory on the flat outputs (x, y, z, yaw), eq. (3).

Coefficients have shape ``(segments, 4, degree + 1)`` in ascending powers of local time
``t - t_i`` (physical units); evaluation runs in the Rust kernel ``avp._avp_rust.eval_spline``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _avp_rust, frames
from . import _validate as v
from ._typing import Array
from .errors import ConfigError

__all__ = ["Derivative", "FlatOutput", "Provenance", "RotorpyTrajectory", "Trajectory"]


MAX_ORDER = 64
"""Highest derivative order evaluated (the kernel's own limit)."""

MAX_SAMPLES = 10**7
"""Most samples :meth:`Trajectory.sample` returns (times only: 80 MB); a sampled export holds
far fewer rows, :data:`avp.export.MAX_EXPORT_SAMPLES`."""

_GRID_CACHE_SAMPLES = 4096
"""Sample grids of at most this many steps are cached (:func:`_sample_grid`)."""


def _sample_grid(dt: float, steps: int, duration: float) -> Array:
    """``min(dt k, duration)`` for ``k = 0..steps``, read-only: :meth:`Trajectory._sample_rel`'s
    grid, cached up to :data:`_GRID_CACHE_SAMPLES` steps (the SQP steps of a plan score their
    candidates on the same one). A read-only view of a read-only array: it cannot be made
    writable, so no caller can change the cached grid."""
    if steps > _GRID_CACHE_SAMPLES:
        return _read_only_view(np.minimum(dt * np.arange(steps + 1), duration))
    return _cached_grid(dt, steps, duration).view()


@functools.lru_cache(maxsize=64)
def _cached_grid(dt: float, steps: int, duration: float) -> Array:
    return _read_only_view(np.minimum(dt * np.arange(steps + 1), duration))


def _read_only_view(a: Array) -> Array:
    a.setflags(write=False)
    return a.view()


TIME_TOL = 1e-9
"""Times this far outside ``[t0, tf]`` (s) are accepted and evaluated at the end points."""


class Derivative(IntEnum):
    """Derivative orders of the flat outputs (as mav_trajectory_generation's derivative_order)."""

    POSITION = 0
    VELOCITY = 1
    ACCELERATION = 2
    JERK = 3
    SNAP = 4


@dataclass(frozen=True)
class FlatOutput:
    """Flat outputs and derivatives at one or many times (leading shape of ``t``)."""

    t: Array
    position: Array
    velocity: Array
    acceleration: Array
    jerk: Array
    snap: Array
    yaw: Array
    yaw_rate: Array
    yaw_acceleration: Array


@dataclass(frozen=True)
class Provenance:
    """Where a planned trajectory came from: it travels with the :class:`Trajectory`.

    Attributes
    ----------
    status:
        The planner's status value (``PlanStatus.value``), e.g. ``"solved: every constraint met"``.
    relaxations:
        Names of the soft constraints relaxed to obtain it (empty: none).
    bounds_certified, workspace_certified:
        The actuator bounds / workspace limits were proven over the whole trajectory.
    fov_dropped:
        The field-of-view rows were dropped (16), or, with a deadline, for lack of time.
    overhang_waypoint:
        Whether :func:`avp.plan_detailed` planned it through :class:`~avp.config.OverhangFlip`'s
        horizontal-thrust waypoint (a planner heuristic, not a relaxation); ``None``: not known
        (other planners, exports written before the field). A replan of a committed plan with
        ``False`` searches without the waypoint first (:func:`avp.plan_detailed`, ``previous``).
    """

    status: str
    relaxations: tuple[str, ...] = ()
    bounds_certified: bool = False
    workspace_certified: bool = False
    fov_dropped: bool = False
    overhang_waypoint: bool | None = None

    def __post_init__(self) -> None:
        # a truth value of another type would silently read as "unknown" (None is not False)
        v.flags("provenance", self)

    @property
    def relaxed(self) -> bool:
        return bool(self.relaxations)

    def __str__(self) -> str:
        certs = []
        certs.append("bounds certified" if self.bounds_certified else "bounds NOT certified")
        certs.append("workspace certified" if self.workspace_certified else "workspace NOT certified")
        relax = f", RELAXED: {', '.join(self.relaxations)}" if self.relaxations else ""
        fov = ", FoV rows dropped" if self.fov_dropped else ""
        return f"{self.status.split(':')[0]} ({'; '.join(certs)}{relax}{fov})"


def _coefficients(coefficients: npt.ArrayLike) -> Array:
    """``(S, 4, N + 1)`` finite coefficients as a new contiguous float array."""
    try:
        c = np.ascontiguousarray(np.array(coefficients, dtype=float))
    except (TypeError, ValueError) as exc:
        raise ConfigError("coefficients", "expected (segments, 4, degree + 1) numbers") from exc
    if c.ndim != 3 or c.shape[1] != 4 or c.shape[0] == 0 or c.shape[2] == 0:
        raise ConfigError("coefficients", f"expected shape (segments >= 1, 4, degree + 1 >= 1), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ConfigError("coefficients", "contains NaN or inf; a trajectory must be finite")
    return c


def _times_array(field: str, values: npt.ArrayLike, n: int) -> Array:
    """``n`` finite times (s) within the time limit as a new contiguous float array."""
    try:
        k = np.ascontiguousarray(np.array(values, dtype=float))
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"expected {n} times (s), got {values!r}") from exc
    if k.shape != (n,):
        raise ConfigError(field, f"expected shape ({n},), got {k.shape}")
    if not np.all(np.isfinite(k)):
        raise ConfigError(field, "contains NaN or inf; a trajectory must be finite")
    v.within(field, k, "time")
    return k


class Trajectory:
    """A spline of ``S`` segments over the knots ``t0 < t1 < ... < tS``.

    Parameters
    ----------
    coefficients:
        ``(S, 4, N + 1)`` ascending-power coefficients of x, y, z, yaw per segment.
    knots:
        ``(S + 1,)`` absolute times (s).
    g:
        Gravity used by the flatness map (m/s^2).

    The spline is held as its start time ``t0`` and the knots relative to it
    (:attr:`knots_rel`, from 0): the segment durations the planner solved for stay exact
    whatever the clock's value, and the certificates read them. An absolute time ``t`` is
    evaluated at ``t - t0`` (``tf`` itself at the spline's end exactly). At a clock value ``c``,
    absolute times resolve to ``ulp(c)`` (2.4e-7 s at UNIX time), so there ``traj(t)`` is the
    spline at a time within that of ``t``; the plan and its certificates are unaffected.
    """

    def __init__(self, coefficients: npt.ArrayLike, knots: npt.ArrayLike, g: float = frames.GRAVITY) -> None:
        c = _coefficients(coefficients)
        k = _times_array("knots", knots, c.shape[0] + 1)
        if np.any(np.diff(k) <= 0):
            raise ConfigError("knots", "must be strictly increasing")
        rel = k - k[0]
        if np.any(np.diff(rel) <= 0):  # knots closer than the rounding of their clock
            raise ConfigError("knots", "segments shorter than the resolution of the clock at these times; "
                              "use a local clock (seconds since the start of the flight)")
        self._init(c, float(k[0]), rel, v.positive_float("g", g))

    @classmethod
    def from_relative_knots(cls, coefficients: npt.ArrayLike, knots_rel: npt.ArrayLike, t0: float = 0.0,
                            g: float = frames.GRAVITY) -> Trajectory:
        """The spline of ``coefficients`` on the knots ``t0 + knots_rel`` (s; ``knots_rel``
        strictly increasing from 0), which it keeps exactly whatever the clock's value
        (:attr:`knots_rel`; :attr:`knots` is then ``t0 + knots_rel`` rounded to the clock)."""
        c = _coefficients(coefficients)
        rel = _times_array("knots_rel", knots_rel, c.shape[0] + 1)
        if rel[0] != 0.0 or np.any(np.diff(rel) <= 0):
            raise ConfigError("knots_rel", "must start at 0.0 and increase strictly")
        start = v.finite_float("t0", t0)
        v.within("t0", np.array([start, start + rel[-1]]), "time")
        self = cls.__new__(cls)
        self._init(c, start, rel, v.positive_float("g", g))
        return self

    def _init(self, coefficients: Array, t0: float, knots_rel: Array, g: float) -> None:
        """Take over ``coefficients`` and ``knots_rel``, read-only."""
        coefficients.setflags(write=False)
        knots_rel.setflags(write=False)
        self._c, self._t0, self._rel, self.g = coefficients, t0, knots_rel, g
        self._knots: Array | None = None
        self._tf = t0 + float(knots_rel[-1])
        self._tol = max(TIME_TOL, 4.0 * math.ulp(max(abs(t0), abs(self._tf))))
        self.provenance: Provenance | None = None
        """Set by the planner: status, relaxations, certificates (``None`` for a bare spline)."""

    @classmethod
    def _trusted(cls, coefficients: Array, t0: float, knots_rel: Array, g: float) -> Trajectory:
        """A trajectory from arrays the caller guarantees valid (the planner's QP solutions:
        finite, shaped, relative knots increasing from 0, ``t0`` within the time limit); they
        are taken over read-only, without copies."""
        self = cls.__new__(cls)
        self._init(coefficients, float(t0), knots_rel, float(g))
        return self

    # -- structure -------------------------------------------------------------------------
    @property
    def coefficients(self) -> Array:
        """Read-only ``(S, 4, N + 1)`` coefficients, ascending powers of ``t - t_i``."""
        return self._c

    @property
    def knots(self) -> Array:
        """Read-only absolute knot times (s): ``t0 + knots_rel``, rounded to the clock (the
        constructor's knots, bit for bit, when their differences from the first are exact: a
        first knot at 0, or all within a factor 2 of each other, as on any clock past the
        flight's duration)."""
        if self._knots is None:
            knots = self._t0 + self._rel
            knots.setflags(write=False)
            self._knots = knots
        return self._knots

    @property
    def knots_rel(self) -> Array:
        """Read-only knot times relative to :attr:`t0` (s), from 0: exact at any clock value."""
        return self._rel

    @property
    def durations(self) -> Array:
        """Segment durations (s)."""
        return np.diff(self._rel)

    @property
    def t0(self) -> float:
        return self._t0

    @property
    def tf(self) -> float:
        return self._tf

    @property
    def duration(self) -> float:
        """``tf - t0`` (s), exact (the last relative knot)."""
        return float(self._rel[-1])

    @property
    def n_segments(self) -> int:
        return int(self._c.shape[0])

    @property
    def degree(self) -> int:
        return int(self._c.shape[2] - 1)

    def __repr__(self) -> str:
        origin = f", {self.provenance}" if self.provenance is not None else ""
        return f"Trajectory(segments={self.n_segments}, degree={self.degree}, t=[{self.t0:.3f}, {self.tf:.3f}] s{origin})"

    # -- evaluation ------------------------------------------------------------------------
    def _times(self, t: Any) -> tuple[Array, tuple[int, ...]]:
        """Times relative to :attr:`t0`, clipped to the spline, and the shape of ``t``."""
        t0, tf, tol = self._t0, self._tf, self._tol
        if isinstance(t, float) and t0 - tol <= t <= tf + tol:  # one time, in range
            return np.array([self.duration if t >= tf else max(t - t0, 0.0)]), ()
        arr, lo, hi = v.finite_times("t", t)
        if arr.size and (lo < t0 - tol or hi > tf + tol):
            raise ConfigError("t", f"times must lie in [{t0}, {tf}] s, got [{lo}, {hi}]")
        return self._relative(arr), arr.shape

    def _relative(self, arr: Array) -> Array:
        """Float times ``arr`` (checked: finite, within the spline up to its tolerance) relative
        to :attr:`t0`, flat, clipped to ``[0, duration]`` (``tf`` itself at the end)."""
        flat = arr.reshape(-1) - self._t0  # a new contiguous array
        if self._t0 != 0.0:  # tf (rounded to the clock) is the end of the spline
            flat[arr.reshape(-1) >= self._tf] = self.duration
        return np.minimum(self.duration, np.maximum(0.0, flat, out=flat), out=flat)  # clip's values, fewer calls

    def _relative_floats(self, times: list[float]) -> list[float]:
        """:meth:`_relative` of finite times within ``[t0, tf]`` in Python floats, the same values
        (the same operations; a handful of times costs less this way than in array calls)."""
        duration, t0, tf = self.duration, self._t0, self._tf  # at t0 = 0, t >= tf gives duration either way
        return [min(duration, max(0.0, duration if t >= tf else t - t0)) for t in times]

    def derivatives(self, t: Any, orders: Any = (0, 1, 2, 3, 4)) -> Array:
        """All four flat outputs for each order: shape ``(len(orders), *shape(t), 4)``."""
        flat, shape = self._times(t)
        items = list(orders) if hasattr(orders, "__iter__") and not isinstance(orders, (str, bytes)) else [orders]
        if any(isinstance(o, (bool, np.bool_, str, bytes)) or not isinstance(o, (int, float, np.integer, np.floating))
               or not float(o).is_integer() for o in items):
            raise ConfigError("order", f"derivative orders are whole numbers, got {orders!r}")
        orders_list = [int(o) for o in items]
        if any(not 0 <= o <= MAX_ORDER for o in orders_list):
            raise ConfigError("order", f"derivative orders must be in [0, {MAX_ORDER}], got {orders_list}")
        out = _avp_rust.eval_spline(self._c, self._rel, flat, orders_list)
        return out.reshape((len(orders_list), *shape, 4))

    def _derivatives_rel(self, tau: Array, orders: list[int]) -> Array:
        """:meth:`derivatives` at times ``tau`` since :attr:`t0` (s, within ``[0, duration]``,
        a flat float array; unchecked): shape ``(len(orders), tau.size, 4)``."""
        return _avp_rust.eval_spline(self._c, self._rel, tau, orders)

    def evaluate(self, t: Any, order: int = 0) -> Array:
        """``order``-th derivative of (x, y, z, yaw): shape ``(*shape(t), 4)``."""
        return self.derivatives(t, (order,))[0]

    def __call__(self, t: Any, order: int = 0) -> Array:
        """``order``-th derivative of the position (W): shape ``(*shape(t), 3)``."""
        return self.evaluate(t, order)[..., :3]

    def yaw(self, t: Any, order: int = 0) -> Array:
        """``order``-th derivative of yaw (rad, rad/s, ...): shape ``shape(t)``."""
        return self.evaluate(t, order)[..., 3]

    def flat_output(self, t: Any) -> FlatOutput:
        """Position to snap and yaw to yaw acceleration at ``t`` (one kernel call)."""
        d = self.derivatives(t)
        return FlatOutput(
            t=np.asarray(t, dtype=float), position=d[0, ..., :3], velocity=d[1, ..., :3],
            acceleration=d[2, ..., :3], jerk=d[3, ..., :3], snap=d[4, ..., :3],
            yaw=d[0, ..., 3], yaw_rate=d[1, ..., 3], yaw_acceleration=d[2, ..., 3],
        )

    # -- flatness map ----------------------------------------------------------------------
    # ``rotor_drag`` (1/s, VehicleLimits.rotor_drag): the thrust is ``a + g e3 + d v`` and its
    # rate ``j + d a`` (0: the drag-free map (11)), as the planner's certificates take it.
    def _thrust_terms(self, t: Any, rotor_drag: float, jerk: bool) -> tuple[Array, Array | None, Array]:
        """``a + d v``, ``j + d a`` (if ``jerk``) and the yaw derivatives ``(psi, psi')``."""
        drag = v.nonnegative_float("rotor_drag", rotor_drag)
        d = self.derivatives(t, (0, 1, 2, 3) if jerk else (0, 1, 2))
        acc = frames.drag_acceleration(d[2, ..., :3], d[1, ..., :3], drag) if drag else d[2, ..., :3]
        j = None
        if jerk:  # (j + d a) is the derivative of (a + d v)
            j = frames.drag_acceleration(d[3, ..., :3], d[2, ..., :3], drag) if drag else d[3, ..., :3]
        return acc, j, np.stack([d[0, ..., 3], d[1, ..., 3]])

    def attitude(self, t: Any, rotor_drag: float = 0.0) -> Array:
        """``R_WB(t)`` from (11), (13): shape ``(*shape(t), 3, 3)``."""
        acc, _, yaw = self._thrust_terms(t, rotor_drag, jerk=False)
        return frames.attitude(acc, yaw[0], self.g)

    def thrust(self, t: Any, mass: float | None = None, rotor_drag: float = 0.0) -> Array:
        """Thrust (10): mass-normalised (m/s^2), or in newtons when ``mass`` (kg) is given."""
        acc, _, _ = self._thrust_terms(t, rotor_drag, jerk=False)
        f = frames.thrust_magnitude(acc, self.g)
        return f if mass is None else v.positive_float("mass", mass) * f

    def body_rates(self, t: Any, rotor_drag: float = 0.0) -> Array:
        """Body angular velocity (rad/s, B frame), (22) and the yaw term of (13)."""
        acc, j, yaw = self._thrust_terms(t, rotor_drag, jerk=True)
        assert j is not None
        return frames.body_rates(acc, j, yaw[0], yaw[1], self.g)

    def sample(self, dt: float) -> Array:
        """Times ``t0, t0 + dt, ...`` up to and including ``tf`` (at most :data:`MAX_SAMPLES`),
        rounded to the clock: on a clock ``c``, a ``dt`` below ``ulp(c)`` (2.4e-7 s at UNIX time)
        repeats times."""
        return np.minimum(self._t0 + self._sample_rel(dt), self._tf)

    def _sample_rel(self, dt: float) -> Array:
        """:meth:`sample` relative to ``t0``: ``0, dt, ...`` up to and including :attr:`duration`
        (read-only: a grid of a few thousand samples or fewer is cached by its arguments,
        :func:`_sample_grid`)."""
        dt = v.positive_float("dt", dt)
        span = self.duration / dt  # a float first: a dt of 1e-308 overflows ceil
        steps = max(1, math.ceil(span - 1e-9)) if span < MAX_SAMPLES else MAX_SAMPLES  # t0 and tf at least
        if steps >= MAX_SAMPLES:
            raise ConfigError("dt", f"{dt:g} s gives {span + 1:.3g} samples over {self.duration:.3g} s; at most "
                              f"{MAX_SAMPLES:g}: sample at dt >= {self.duration / (MAX_SAMPLES - 1):.3g} s")
        return _sample_grid(dt, int(steps), self.duration)

    # -- exports (avp.export) ---------------------------------------------------------------
    def to_json(self, path: Any = None, *, rate: float | None = None, indent: int | None = None,
                rotor_drag: float = 0.0) -> str:
        """JSON text with the exact coefficients (and samples at ``rate`` Hz if given, their
        thrust, attitude and body rates with ``rotor_drag``, :func:`avp.export.sample_table`);
        also written to ``path`` if given. :meth:`from_json` reads it back. ``indent`` is
        ``json.dumps``'s: ``None`` (one line), a number of spaces or a whitespace string."""
        from . import export

        return export.write_json(self, path, rate=rate, indent=indent, rotor_drag=rotor_drag)

    def to_npz(self, path: Any, *, rate: float | None = None, rotor_drag: float = 0.0) -> Path:
        """NumPy ``.npz`` with the exact coefficients (and samples at ``rate`` Hz if given)."""
        from . import export

        return export.write_npz(self, path, rate=rate, rotor_drag=rotor_drag)

    def to_csv(self, path: Any, *, rate: float | None = None, rotor_drag: float = 0.0) -> Path:
        """CSV of samples at ``rate`` Hz (:data:`avp.export.SAMPLE_COLUMNS`), or without a rate
        one row of exact coefficients per segment and flat output (:meth:`from_csv` reads it)."""
        from . import export

        return export.write_csv(self, path, rate=rate, rotor_drag=rotor_drag)

    @classmethod
    def from_json(cls, source: Any) -> Trajectory:
        """A trajectory from :meth:`to_json` output (a path or the JSON text)."""
        from . import export

        return export.read_json(source)

    @classmethod
    def from_npz(cls, path: Any) -> Trajectory:
        from . import export

        return export.read_npz(path)

    @classmethod
    def from_csv(cls, path: Any) -> Trajectory:
        """A trajectory from a coefficient CSV written by :meth:`to_csv` without a rate."""
        from . import export

        return export.read_csv(path)

    def to_rotorpy(self) -> RotorpyTrajectory:
        """Adapter with rotorpy's trajectory protocol ``update(t) -> flat_output dict``."""
        return RotorpyTrajectory(self)


class RotorpyTrajectory:
    """rotorpy trajectory protocol: ``update(t)`` with keys ``x, x_dot, x_ddot, x_dddot,
    x_ddddot, yaw, yaw_dot, yaw_ddot``. Time is relative to the plan's start (rotorpy starts at
    0) and held at the end points outside the plan."""

    def __init__(self, trajectory: Trajectory) -> None:
        self.trajectory = trajectory

    def update(self, t: float) -> dict[str, Any]:
        """Flat outputs at ``t`` (s since the plan's start, one number): a :class:`ConfigError`
        on ``t`` for anything else (as :class:`Trajectory`'s evaluation: NaN, inf, a string,
        a boolean, ``None``, an array)."""
        tr = self.trajectory
        if type(t) is not float or not math.isfinite(t):  # the fast path: rotorpy's float clock
            arr, lo, _ = v.finite_times("t", t)
            if arr.shape != ():
                raise ConfigError("t", f"expected one time in s, got shape {arr.shape}")
            t = lo
        d = tr._derivatives_rel(np.array([min(max(t, 0.0), tr.duration)]), [0, 1, 2, 3, 4])[:, 0]
        return {
            "x": d[0, :3], "x_dot": d[1, :3], "x_ddot": d[2, :3], "x_dddot": d[3, :3],
            "x_ddddot": d[4, :3], "yaw": float(d[0, 3]), "yaw_dot": float(d[1, 3]),
            "yaw_ddot": float(d[2, 3]),
        }
