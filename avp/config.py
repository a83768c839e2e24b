"""Planner configuration with the paper's defaults (Sec. VI-A): vehicle limits, contact
velocity, pre-impact band (14), time allocation and solver settings.

All fields are SI (m, s, rad, N). Frozen dataclasses validated on construction; derive a
variant with :func:`dataclasses.replace`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from . import _validate as v
from ._values import fields_equal, fields_hash
from .bounds import check_body_rate_degree
from .camera import Camera
from .errors import ConfigError
from .frames import GRAVITY

__all__ = [
    "BoundsPolicy",
    "ContactVelocity",
    "FovConfig",
    "FovPointPolicy",
    "HalfSpace",
    "OverhangFlip",
    "PlannerConfig",
    "PreImpactMode",
    "QpForm",
    "Relaxation",
    "ReplanConfig",
    "Sphere",
    "TimeAllocation",
    "TimeSearch",
    "VehicleLimits",
    "Workspace",
]


class PreImpactMode(Enum):
    """How the pre-impact attitude band (14) is imposed over ``[t_f - t_k, t_f)``."""

    PAPER = "paper: componentwise box between c0 and (1+q) c0, eq. (14)"
    CONE = "cone: tilt of a + g e3 from s3 in a polyhedral cone, thrust along s3 in [alpha, (1+q) alpha]"
    OFF = "off: no pre-impact band"


class QpForm(Enum):
    """How the QP (5) is handed to the solver."""

    REDUCED = "reduced: equalities eliminated by a null-space basis (exact to rounding)"
    FULL = "full: coefficients with A c = b passed to the solver as is"


MAX_SEGMENTS = 32
"""Most spline segments a plan may have (the QP grows with their square; 200 took minutes)."""

ALPHA_NOMINAL = 4.0
"""Nominal mass-normalised contact thrust (m/s^2) on steep pads, as in the paper's experiments."""


GROUND_CLEARANCE = 0.3
"""Height (m) above a world's ground below which ``avp demo`` and the simulator's default planner
configuration (``avp.sim.run``, the campaign runner's unless it sets a ground; the ground is
``SimScenario.ground_z``) do not let the centre of mass go (``Workspace.ground_z``): the
vehicle's size and its tracking error. With the limit at the ground itself, moving-platform
plans grazed it and crashed (docs/moving.md), and demo plans passed 5 mm above it. A start or
pad closer to the ground than this gets no plan from those configurations (a typed
``ConfigError`` naming the ground): pass a configuration with its own ``workspace.ground_z``."""


def _solver_options(value: Any) -> tuple[tuple[str, Any], ...]:
    """``PlannerConfig.solver_options`` as ``((name, value), ...)``, from a mapping or from
    pairs, names being Python identifiers (the back-end's keyword arguments)."""
    hint = "must be the back-end's keyword arguments: a dict {name: value} or pairs ((name, value), ...)"
    if isinstance(value, Mapping):
        pairs: Any = tuple(value.items())
    elif isinstance(value, (list, tuple)):
        pairs = tuple(value)
    else:
        raise ConfigError("config.solver_options", f"{hint}, got {value!r}")
    for pair in pairs:
        if not (isinstance(pair, (list, tuple)) and len(pair) == 2 and isinstance(pair[0], str)
                and pair[0].isidentifier()):
            raise ConfigError("config.solver_options", f"{hint}, got {pair!r} in {value!r}")
    return tuple((str(k), val) for k, val in pairs)


@v.typed_keywords("limits")
@dataclass(frozen=True)
class VehicleLimits:
    """Vehicle mass and actuator limits, checked by the bound certificates (15), (21)-(29).

    ``thrust_rate_max`` bounds ``|d tau/dt|`` through ``m |j|`` (21); ``tilt_rate_max`` bounds
    ``sqrt(w1^2 + w2^2)`` exactly through ``|j|^2 <= w^2 |a + g e3|^2`` (22) (equal to the body
    rate for a yaw-free, roll-free manoeuvre); ``body_rate_max`` bounds ``|w|`` including the yaw
    term, conservatively, with the roll bound it needs (25) certified too. The rate limits may be ``inf`` (not
    checked). Defaults: 0.5 kg, thrust in [0.5, 2 g] m/s^2 mass-normalised, tilt rate 10 rad/s
    (without a rate limit a relaxed plan can be "certified" while flipping at 100+ rad/s).

    ``rotor_drag`` (1/s, default 0) is the mass-normalised linear rotor drag ``d`` of Faessler,
    Franchi and Scaramuzza, "Differential Flatness of Quadrotor Dynamics Subject to Rotor Drag":
    the rotors' drag force is ``-m d v`` in the rotor plane (``diag(d, d, d_z)`` in B), so the
    thrust axis is ``b3 || a + g e3 + d v``. The perching constraints use it: at contact the
    *thrust* is along ``s3`` (12) and the pre-impact band (14) bounds ``a + d v`` instead of
    ``a`` (on a wall with a 2 m/s slide and ``d = 0.29 /s`` the drag-free condition leaves the
    thrust 8 deg off the normal). The FoV rows (8)-(9) and the visibility score that accepts an
    SQP step take the camera's attitude from the same thrust (:func:`avp.qp.fov.fov_blocks`; on
    rotorpy's wall the drag turned the camera by 4-8 deg, which put the pad up to 3 deg outside
    the 35 deg cone for a second of the approach). A line perch (:func:`avp.plan_line`) takes
    its contact thrust, its rest at contact (``j + d a = 0``) and its flip rows on the same
    thrust (:func:`avp.qp.line.line_terminal_blocks`). The bound certificates prove the thrust
    range, thrust rate, tilt rate and body rate on that thrust and its rate ``j + d a``
    (:func:`avp.bounds.certify_trajectory`), and the duration search, the failure message and
    the CLI's summary measure it (``Trajectory.attitude``, ``thrust`` and ``body_rates`` take
    ``rotor_drag=d``, as do the sampled exports). Without that argument they keep the
    drag-free map (11), whose attitude differs by up to ``atan(d |v| / |a + g e3|)``.
    """

    mass: float = 0.5
    thrust_min: float = 0.5 * 0.5  # N, 0.5 m/s^2 mass-normalised
    thrust_max: float = 0.5 * 2.0 * GRAVITY  # N, 2 g
    thrust_rate_max: float = math.inf  # N/s
    tilt_rate_max: float = 10.0  # rad/s, on sqrt(w1^2 + w2^2)
    body_rate_max: float = math.inf  # rad/s, on |w| including yaw (roll level certified)
    rotor_drag: float = 0.0  # 1/s, mass-normalised linear rotor drag d (docstring)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", v.positive_float("limits.mass", self.mass))
        for name in ("rotor_drag", "thrust_min"):  # 1/s, N
            object.__setattr__(self, name, v.nonnegative_float(f"limits.{name}", getattr(self, name)))
        object.__setattr__(self, "thrust_max", v.positive_float("limits.thrust_max", self.thrust_max))
        if self.thrust_max / self.mass > v.LIMITS["acceleration"][0]:
            raise ConfigError("limits.thrust_max", f"thrust_max / mass = {self.thrust_max / self.mass:.3g} m/s^2 is beyond "
                              f"{v.LIMITS['acceleration'][0]:g} m/s^2: check the units (N, kg) and limits.mass")
        if self.thrust_min >= self.thrust_max:
            raise ConfigError(
                "limits.thrust_min",
                f"({self.thrust_min} N) must be below limits.thrust_max ({self.thrust_max} N)",
            )
        for name in ("thrust_rate_max", "tilt_rate_max", "body_rate_max"):
            object.__setattr__(self, name, v.positive_float(f"limits.{name}", getattr(self, name), allow_inf=True))

    @property
    def accel_min(self) -> float:
        """Mass-normalised minimum thrust (m/s^2)."""
        return self.thrust_min / self.mass

    @property
    def accel_max(self) -> float:
        """Mass-normalised maximum thrust (m/s^2)."""
        return self.thrust_max / self.mass


@v.typed_keywords("contact_velocity")
@dataclass(frozen=True)
class ContactVelocity:
    """Velocity at contact in the target frame S; ``None`` leaves a component free.

    ``normal`` is ``v . s3`` (negative = into the pad; paper: 0.3 m/s into it), ``slope`` is
    ``v . s1`` (negative = down the slope; paper: 2 m/s down), ``lateral`` is ``v . s2``.
    "Slope" is ``s1`` as the pad's frame gives it: up the slope for a frame built by
    ``PerchTarget.from_incline`` or ``from_normal`` (without ``up_slope``); a frame whose
    ``s1`` is turned about the normal turns the slide with it.
    With ``scale_slope_with_incline`` the slide is multiplied by ``sin(incline)``, so it is the
    paper's value on a wall and vanishes on a level pad where "down the slope" has no meaning.
    """

    normal: float | None = -0.3
    slope: float | None = -2.0
    lateral: float | None = 0.0
    scale_slope_with_incline: bool = True

    def __post_init__(self) -> None:
        v.flags("contact_velocity", self)
        for name in ("normal", "slope", "lateral"):
            val = getattr(self, name)
            if val is not None:
                object.__setattr__(self, name, v.finite_float(f"contact_velocity.{name}", val))
                v.within(f"contact_velocity.{name}", getattr(self, name), "velocity")

    def components(self, incline: float) -> tuple[float | None, float | None, float | None]:
        """``(v.s1, v.s2, v.s3)`` requested at contact for a pad of this ``incline``."""
        slope = self.slope
        if slope is not None and self.scale_slope_with_incline:
            slope = slope * math.sin(incline)
        return slope, self.lateral, self.normal


@v.typed_keywords("time_allocation")
@dataclass(frozen=True)
class TimeAllocation:
    """Initial duration rule: ``T = t_attitude + sqrt(2 d / a_nominal) + |v0| / a_nominal``.

    ``d`` is the start-to-target distance; the speed term adds the time to bleed off ``|v0|``.
    Segments share the total equally. With the defaults: 1.42 / 2.07 / 2.94 s at 1.5 / 3.5 / 7.5
    m from rest. ``a_nominal = 2.0 m/s^2`` was measured in closed loop in the realistic
    simulator (``docs/decisions.md``): the extra time puts more of the camera's close detections
    before the last moment a correction can still be tracked. Against 2.5 m/s^2 on a wall, AVP
    perched 78 / 82 instead of 57 / 70 of 100 unused seeds (4.5 / 7.5 m). Shorter totals pitch
    the vehicle past the camera's half-angle at launch (target visibility 36-40 % at 4.6
    m/s^2); longer ones make the min-snap path dip below a wall target (from hover 7.5 m from a
    wall, 1.52 m below the pad at 2.0 m/s^2, 1.16 m at 2.5; below a floor at z = 0 for a pad
    1.5 m high): set ``Workspace.ground_z`` wherever there is a ground.
    """

    nominal_acceleration: float = 2.0
    attitude_time: float = 0.2
    min_duration: float = 0.4

    def __post_init__(self) -> None:
        v.positive_float("time_allocation.nominal_acceleration", self.nominal_acceleration)
        v.within("time_allocation.attitude_time",
                 v.nonnegative_float("time_allocation.attitude_time", self.attitude_time), "duration")
        v.within("time_allocation.min_duration",
                 v.positive_float("time_allocation.min_duration", self.min_duration), "duration")

    def total(self, distance: float, speed: float) -> float:
        a = self.nominal_acceleration
        return max(self.min_duration, self.attitude_time + math.sqrt(2.0 * distance / a) + speed / a)


@v.typed_keywords("flip")
@dataclass(frozen=True)
class OverhangFlip:
    """Thrust through the horizontal on an overhang (incline above ``min_incline``, up to a
    ceiling at 180 deg).

    The thrust ``f = a + g e3`` must turn from about ``+e3`` (flying) to ``s3`` (pointing down at
    contact). Min-snap alone interpolates it through (almost) zero: every ceiling plan failed
    ``thrust_min`` and the tilt rate (up to 550 rad/s). The planner therefore asks, at
    ``t_w = t_f - t_k - (incline - 90 deg) / turn_rate``, for a horizontal thrust along the
    horizontal part ``u`` of ``s1`` of at least ``thrust`` (m/s^2, mass-normalised):
    ``f(t_w) . e3 = 0``, ``f(t_w) . (e3 x u) = 0``, ``f(t_w) . u >= thrust`` (linear rows;
    ``thrust`` defaults to ``max(2.5, 2 f_min)``, below the middle of the thrust range).
    ``turn_rate`` defaults to 0.7 x ``limits.tilt_rate_max`` (7 rad/s without a tilt limit):
    the time left to turn from the horizontal to ``s3`` before the band (14). With ``cone_band``
    an overhang's pre-impact band (14) in PAPER mode is imposed as the tilt cone (CONE): the
    componentwise box pins the thrust upside down and blocked most overhangs. Measured in
    ``docs/decisions.md``.

    Parameters
    ----------
    enabled:
        Add the horizontal-thrust waypoint on overhangs. The waypoint is the planner's device,
        not the user's constraint: when no duration certifies with it, :func:`avp.plan_detailed`
        searches again without it (and with the band as asked: ``cone_band``'s cone stays)
        before relaxing anything (noisy wall estimates that tip just
        past ``min_incline`` otherwise planned only with relaxations: 2 of 20 first plans at 7.5 m
        in the realistic simulator). A replan of a committed plan made without it (its
        ``provenance.overhang_waypoint`` is ``False``: the pad was no overhang then, or the
        waypoint was dropped) searches without it first, then with it.
    min_incline:
        Pads steeper than this (rad) count as overhangs.
    cone_band:
        On overhangs, impose a PAPER-mode band (14) as the tilt cone instead.
    thrust:
        Least horizontal thrust at the waypoint (m/s^2, mass-normalised); ``None``:
        ``max(2.5, 2 f_min)`` kept below the middle of the thrust range.
    turn_rate:
        Planned turn rate of the thrust from the horizontal to ``s3`` (rad/s); ``None``:
        0.7 x ``limits.tilt_rate_max`` (7 rad/s without a tilt limit).
    """

    enabled: bool = True
    min_incline: float = math.radians(95.0)
    cone_band: bool = True
    thrust: float | None = None
    turn_rate: float | None = None

    def __post_init__(self) -> None:
        v.flags("flip", self)
        if not math.pi / 2 <= v.finite_float("flip.min_incline", self.min_incline) <= math.pi:
            raise ConfigError("flip.min_incline", f"must be in [pi/2, pi] rad, got {self.min_incline}")
        if self.thrust is not None:
            v.positive_float("flip.thrust", self.thrust)
        if self.turn_rate is not None:
            v.positive_float("flip.turn_rate", self.turn_rate)

    def horizontal_thrust(self, limits: VehicleLimits) -> float:
        """Least horizontal thrust (m/s^2) at the waypoint: ``thrust``, or by default
        ``max(2.5, 2 f_min)`` kept below the middle of the thrust range."""
        if self.thrust is not None:
            return self.thrust
        lo, hi = limits.accel_min, limits.accel_max
        return min(max(2.5, 2.0 * lo), 0.5 * (lo + hi))

    def rate(self, limits: VehicleLimits) -> float:
        """The planned turn rate (rad/s) of the thrust from the horizontal to ``s3``."""
        if self.turn_rate is not None:
            return self.turn_rate
        return 0.7 * (limits.tilt_rate_max if math.isfinite(limits.tilt_rate_max) else 10.0)


class TimeSearch(Enum):
    """How durations change when a bound is violated (Sec. V-C)."""

    PAPER = "paper: lengthen every segment by a factor until the bounds hold (capped)"
    BIDIRECTIONAL = "bidirectional: try longer and shorter totals alternately (feasibility is not monotone in T)"
    SCALING = "scaling: predict the total from how the bounds scale with time, stop when that stalls"


class Relaxation(Enum):
    """What the planner may relax, in order, when no duration gives certified bounds."""

    ALPHA_RANGE = "contact thrust alpha becomes a decision variable inside the thrust limits"
    FREE_SLIDE = "the slide along the slope (v.s1) is left free"
    CONE_BAND = "pre-impact band (14) replaced by the tilt cone"
    NO_BAND = "pre-impact band (14) dropped"


@v.typed_keywords("bounds")
@dataclass(frozen=True)
class BoundsPolicy:
    """Certification of the actuator bounds and what to change when they fail (Alg. 1).

    Parameters
    ----------
    certify:
        Certify the vehicle limits on the whole trajectory after each solve.
    time_search:
        :class:`TimeSearch`.
    factors:
        BIDIRECTIONAL: total-duration factors tried in order. SCALING: their range bounds the
        total-duration factor, and they are tried in order only after a plan whose bounds hold
        but whose workspace does not.
    growth, max_steps:
        PAPER: factor per step and the cap on steps. SCALING: ``max_steps`` caps the predicted
        steps per relaxation stage.
    relaxations:
        Tried in order, cumulatively, each with the time search, when no duration works.
    """

    certify: bool = True
    time_search: TimeSearch = TimeSearch.SCALING
    factors: tuple[float, ...] = (1.15, 0.87, 1.3, 0.77, 1.5, 0.67, 1.75, 2.0, 2.5, 3.0)
    growth: float = 1.2
    max_steps: int = 10
    relaxations: tuple[Relaxation, ...] = (
        Relaxation.FREE_SLIDE, Relaxation.CONE_BAND, Relaxation.NO_BAND, Relaxation.ALPHA_RANGE,
    )

    def __post_init__(self) -> None:
        v.flags("bounds", self)
        if not isinstance(self.time_search, TimeSearch):
            raise ConfigError("bounds.time_search", f"must be an avp.TimeSearch (e.g. TimeSearch.SCALING), got "
                              f"{self.time_search!r}")
        relax = v.sequence("bounds.relaxations", self.relaxations, "avp.Relaxation", (Relaxation,))
        for i, r in enumerate(relax):
            if not isinstance(r, Relaxation):
                raise ConfigError(f"bounds.relaxations[{i}]", f"must be an avp.Relaxation (e.g. Relaxation.FREE_SLIDE), "
                                  f"got {r!r}")
        object.__setattr__(self, "relaxations", relax)
        factors = v.sequence("bounds.factors", self.factors, "duration factors")
        object.__setattr__(self, "factors", tuple(v.positive_float(f"bounds.factors[{i}]", f)
                                                  for i, f in enumerate(factors)))
        for i, f in enumerate(self.factors):
            if not 1e-3 <= f <= 1e3:
                raise ConfigError(f"bounds.factors[{i}]", f"must be in [1e-3, 1e3] (a factor on the durations), got {f}")
        growth = v.finite_float("bounds.growth", self.growth)
        if not 1.0 < growth <= 10.0:
            raise ConfigError("bounds.growth", f"must be in (1, 10], got {self.growth}")
        v.integer("bounds.max_steps", self.max_steps, 0, 100)

    def schedule(self) -> tuple[float, ...]:
        """Duration factors to try after the first solve, in order (SCALING: its fallback list)."""
        if self.time_search is TimeSearch.PAPER:
            return tuple(self.growth ** (k + 1) for k in range(self.max_steps))
        return self.factors


@v.typed_keywords("workspace.half_spaces")
@dataclass(frozen=True, eq=False)
class HalfSpace:
    """The allowed side of a plane: positions ``p`` with ``(p - point) . normal > 0`` (W, m).

    A ceiling at 3 m: ``HalfSpace(point=(0, 0, 3), normal=(0, 0, -1))``.
    """

    point: Any
    normal: Any

    __eq__ = fields_equal  # values, not identity (module _values)
    __hash__ = fields_hash

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", v.frozen_array("workspace.half_spaces.point", self.point, (3,)))
        v.within("workspace.half_spaces.point", self.point, "position")
        object.__setattr__(self, "normal", v.unit_vector("workspace.half_spaces.normal", self.normal))

    @property
    def offset(self) -> float:
        """``d`` of ``normal . p > d``."""
        return float(self.normal @ self.point)


@v.typed_keywords("workspace.spheres")
@dataclass(frozen=True, eq=False)
class Sphere:
    """A keep-out ball: positions with ``|p - center| > radius`` (W, m)."""

    center: Any
    radius: float

    __eq__ = fields_equal  # values, not identity (module _values)
    __hash__ = fields_hash

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", v.frozen_array("workspace.spheres.center", self.center, (3,)))
        v.within("workspace.spheres.center", self.center, "position")
        object.__setattr__(self, "radius", v.positive_float("workspace.spheres.radius", self.radius))
        v.within("workspace.spheres.radius", self.radius, "distance")


@v.typed_keywords("workspace")
@dataclass(frozen=True)
class Workspace:
    """Where the vehicle's centre of mass may go: certified over the whole plan, never relaxed.

    Every active limit becomes linear QP rows on samples (refined where the certificate finds a
    violation) and a certificate of the exact polynomial over every segment, proven in Rust
    (:mod:`avp.safety`, ``docs/bounds.md``). The time search and the relaxations may change the
    soft choices (slide, band, alpha), never these.

    Parameters
    ----------
    perch_clearance:
        Stay strictly on the outward side of the perch pad's plane until contact:
        ``(p(t) - point) . s3 > body_offset`` for ``t < t_f`` (on by default).
    body_offset:
        Distance (m) from the centre of mass to the contact point along ``-b3`` (landing gear
        or body radius). The centre of mass reaches ``point + body_offset * s3`` at contact and
        keeps at least this distance from the pad's plane before, which keeps every point of the
        body within ``body_offset`` of the centre of mass out of the plane at any attitude.
    ground_z:
        Minimum height of the centre of mass (m), or ``None`` for no ground (``avp demo``
        passes :data:`GROUND_CLEARANCE` above its ground at z = 0).
    max_speed:
        Limit on ``|v|`` (m/s); ``inf`` to skip.
    half_spaces, spheres:
        Extra :class:`HalfSpace` limits (ceilings, neighbouring walls) and :class:`Sphere`
        keep-out zones.
    samples_per_segment:
        Initial number of QP sample rows per segment and limit.
    refinement_rounds:
        Re-solves with denser, tightened rows around a certified violation before the attempt
        counts as failed.
    refinement_margin:
        Tightening (m; m/s for the speed) added per refinement round on the refined rows.
    """

    perch_clearance: bool = True
    body_offset: float = 0.0
    ground_z: float | None = None
    max_speed: float = math.inf
    half_spaces: tuple[HalfSpace, ...] = ()
    spheres: tuple[Sphere, ...] = ()
    samples_per_segment: int = 8
    refinement_rounds: int = 4
    refinement_margin: float = 0.005

    def __post_init__(self) -> None:
        v.flags("workspace", self)
        object.__setattr__(self, "body_offset", v.nonnegative_float("workspace.body_offset", self.body_offset))
        v.within("workspace.body_offset", self.body_offset, "distance")
        if self.ground_z is not None:
            object.__setattr__(self, "ground_z", v.finite_float("workspace.ground_z", self.ground_z))
            v.within("workspace.ground_z", self.ground_z, "position")
        v.positive_float("workspace.max_speed", self.max_speed, allow_inf=True)
        for name, kind in (("half_spaces", HalfSpace), ("spheres", Sphere)):
            object.__setattr__(self, name, v.sequence(f"workspace.{name}", getattr(self, name),
                                                      f"avp.{kind.__name__}", (kind,)))
        for h in self.half_spaces:
            if not isinstance(h, HalfSpace):
                raise ConfigError("workspace.half_spaces", f"expected avp.HalfSpace items, got {type(h).__name__}")
        for sph in self.spheres:
            if not isinstance(sph, Sphere):
                raise ConfigError("workspace.spheres", f"expected avp.Sphere items, got {type(sph).__name__}")
        for name, lo, hi in (("samples_per_segment", 2, 1000), ("refinement_rounds", 0, 100)):
            v.integer(f"workspace.{name}", getattr(self, name), lo, hi)
        object.__setattr__(self, "refinement_margin",
                           v.nonnegative_float("workspace.refinement_margin", self.refinement_margin))

    @property
    def active(self) -> bool:
        """Any limit to keep."""
        return (self.perch_clearance or self.ground_z is not None or math.isfinite(self.max_speed)
                or bool(self.half_spaces) or bool(self.spheres))


class FovPointPolicy(Enum):
    """What to do with a FoV point whose linearised row (8) cannot hold anywhere inside its trust
    region (9) (the target is too far outside the cone at the linearisation point).

    Such a row makes the whole QP infeasible, so the fallback (16) would drop *every* FoV row.
    """

    SKIP = "skip: leave the point without a FoV row"
    PROGRESS = "progress: require a fraction of the decrease of h reachable inside the trust region"
    KEEP = "keep: place the row as is (the QP is infeasible and the fallback (16) fires)"


@v.typed_keywords("fov")
@dataclass(frozen=True)
class FovConfig:
    """Perception-aware planning: FoV rows (8) with trust region (9) and the fallback (16).

    Parameters
    ----------
    enabled:
        Place FoV rows at all (``False``: the plain perching QP).
    n_points:
        ``n_p``, the number of linearisation points spread equally over the remaining trajectory
        up to the gate (paper: 8).
    trust_position, trust_acceleration, trust_yaw:
        Half-widths of the trust region (9) around the linearisation point: 0.05 m, 0.2 m/s^2,
        0.1 rad. The paper writes 2-norms; we impose a **box** (per component), the natural linear
        form: it contains the paper's ball and is at most ``sqrt(3)`` wider along a diagonal.
        With ``VehicleLimits.rotor_drag = d`` the acceleration box is on ``a + d v``, the
        variable the rows are linearised in (:func:`avp.qp.fov.fov_blocks`).
    gate:
        Window before contact (s) without FoV rows. The final pitch-up turns a front camera away
        from a steep pad, so rows there make the QP infeasible (docs/perception.md measures it).
    point_policy, progress_fraction:
        :class:`FovPointPolicy` for points whose row cannot hold inside the trust region; with
        ``PROGRESS`` the row asks for ``progress_fraction`` of the largest linearised decrease of
        ``h`` the box allows.
    reach_fraction:
        A point counts as out of reach (the policy applies) when meeting its row would take more
        than this fraction of the largest linearised decrease inside the box (1: only truly
        impossible rows; smaller values avoid the thin feasible sets on which first-order
        back-ends report infeasibility).
    margin:
        Right-hand side of the linearised row in units of ``|n_d|``: ``h/|n_d| <= -margin``
        (0: the cone itself), i.e. the narrower cone ``cos(angle) >= cos(half_fov) + margin``
        (:meth:`Camera.narrowed`; 0.04 is about 4 deg inside a 35 deg cone). A small positive
        value absorbs linearisation error, or a vehicle whose attitude departs from the model by
        a few degrees. A first plan's SQP scores its steps' visibility in the same narrowed cone
        (:attr:`score_camera`), so a step that meets the margin is kept; scored in the cone
        itself, such steps could lower the score and be rejected (on a drag-aware wall perch the
        margin then changed nothing: ``docs/perception.md``).
    sqp_iterations:
        Cap on SQP steps for a first plan (no previous plan): solve without FoV, then linearise
        around the last solution and re-solve while the visibility improves, at most this often.
    sqp_min_gain:
        A first plan takes a further SQP step only when its last kept step raised the visibility
        (the mean of the time and path fractions, as the log prints it) by at least this much;
        0 (the default): while it improves at all (a step is kept only when it raises the
        visibility by more than 5e-5, so smaller values change nothing). A latency knob, off by
        default because it lowers the visibility of some plans: ``docs/performance.md`` measures
        the trade (``benchmarks/sweep_sqp_gain.py``).
    fallback_max_iter:
        Iteration cap given to iterative back-ends (proxqp, osqp) for the QPs with FoV rows, so an
        incompatible problem (16) is declared quickly; ``None``: the back-end's setting.
    camera:
        :class:`Camera` (front camera, 35 deg half-angle).
    """

    enabled: bool = True
    n_points: int = 8
    trust_position: float = 0.05
    trust_acceleration: float = 0.2
    trust_yaw: float = 0.1
    gate: float = 0.0
    point_policy: FovPointPolicy = FovPointPolicy.SKIP
    progress_fraction: float = 0.5
    reach_fraction: float = 0.5
    margin: float = 0.0
    sqp_iterations: int = 3
    sqp_min_gain: float = 0.0
    fallback_max_iter: int | None = 4000
    camera: Camera = field(default_factory=Camera)

    def __post_init__(self) -> None:
        v.flags("fov", self)
        for name, lo, hi in (("n_points", 1, 1000), ("sqp_iterations", 1, 100)):
            v.integer(f"fov.{name}", getattr(self, name), lo, hi)
        for name in ("trust_position", "trust_acceleration", "trust_yaw"):
            v.positive_float(f"fov.{name}", getattr(self, name), allow_inf=True)
        g = v.finite_float("fov.gate", self.gate)
        if g < 0.0:
            raise ConfigError("fov.gate", f"must be >= 0 s, got {g}")
        if not isinstance(self.point_policy, FovPointPolicy):
            raise ConfigError("fov.point_policy", f"must be a FovPointPolicy, got {self.point_policy!r}")
        pf = v.finite_float("fov.progress_fraction", self.progress_fraction)
        if not 0.0 < pf <= 1.0:
            raise ConfigError("fov.progress_fraction", f"must be in (0, 1], got {pf}")
        rf = v.finite_float("fov.reach_fraction", self.reach_fraction)
        if not 0.0 < rf <= 1.0:
            raise ConfigError("fov.reach_fraction", f"must be in (0, 1], got {rf}")
        mg = v.finite_float("fov.sqp_min_gain", self.sqp_min_gain)
        if not 0.0 <= mg <= 1.0:
            raise ConfigError("fov.sqp_min_gain", f"must be in [0, 1] (a visibility fraction), got {mg}")
        m = v.finite_float("fov.margin", self.margin)
        if not 0.0 <= m < 1.0:
            raise ConfigError("fov.margin", f"must be in [0, 1), got {m}")
        if self.fallback_max_iter is not None and (
            isinstance(self.fallback_max_iter, bool)
            or not isinstance(self.fallback_max_iter, (int, np.integer))
            or self.fallback_max_iter < 1
        ):
            raise ConfigError("fov.fallback_max_iter", f"must be None or an integer >= 1, got {self.fallback_max_iter!r}")
        if not isinstance(self.camera, Camera):
            raise ConfigError("fov.camera", f"must be an avp.Camera, got {type(self.camera).__name__}")

    @cached_property
    def score_camera(self) -> Camera | None:
        """The camera a first plan's SQP scores visibility with: :attr:`camera` with the cone the
        rows ask for (:meth:`Camera.narrowed` by :attr:`margin`; the camera itself for 0),
        ``None`` when no direction meets the rows (every plan then scores 0)."""
        return self.camera.narrowed(self.margin)


@v.typed_keywords("config")
@dataclass(frozen=True)
class PlannerConfig:
    """Everything one plan needs besides the start state and the target.

    Parameters
    ----------
    n_segments:
        Spline shape: ``n_segments`` polynomials of ``degree`` per flat output.
    degree:
        Degree of each polynomial (paper: 7). Above degree 10 with many segments the plans are
        slow and poor: in the monomial basis of the coefficients the reduced QP is
        ill-conditioned (condition numbers 3e13 to 3e21),
        DAQP's solution is far from the optimum, fails the certificates, and the relaxation
        stages are solved in turn, each a dense QP in the ``4 n_segments (degree + 1)``
        coefficients. Measured (certificates and FoV off; wall and 45 deg pads from 3 to
        7.5 m): up to degree 10 the snap cost is within 0.1 % of the optimum at 1 to 32
        segments; at degree 11 from 10 segments, 12 to 14 from 8, 15 and 20 from 6 it exceeds
        it, by 0.2 % up to a factor 6e4 (degree 15, 32 segments). With the certificates (one
        BLAS thread), 32 segments of degree 15 took 17 s (10 QPs of 1404 unknowns left by the
        elimination of 2048 coefficients: 10.6 s in DAQP, 5.4 s in the eliminations) and ended
        ``BOUNDS_NOT_CERTIFIED``; of degree 10, 0.5 s and one QP. Refine with segments at degree
        <= 10: where no inequality row is active, a snap-optimal piece is of degree 7 anyway.
    position_cost_order, yaw_cost_order:
        ``j`` of the cost (4): 4 (snap) for position, 2 or 3 for yaw.
    continuity_order:
        Highest derivative continuous at interior knots (4 = snap); at least 3 (jerk). The
        certificates bound the thrust, tilt and body rates within each segment; below 3 the
        attitude (an acceleration jump) or the body rates (a jerk jump) jump at a knot, which no
        vehicle flies (with 0, a wall plan jumped 8.4 m/s and 161 deg at a knot and was
        reported certified).
    alpha:
        Mass-normalised thrust at contact (m/s^2) in (12): ``a(t_f) = alpha s3 - g e3``.
        ``None`` (default): ``alpha_nominal`` on steep pads, raised to ``g cos(incline)`` on
        flatter ones (:meth:`contact_alpha`), so the acceleration along the normal at contact,
        ``alpha - g cos(incline)``, is never negative. With a smaller thrust a vehicle that
        arrives slowly (0.3 m/s) must have come from behind the pad: on a floor, alpha = 4 puts
        the path 2 cm below the floor 0.15 s before contact, and no trajectory meets the band
        (14) with the perch-plane clearance.
    alpha_nominal:
        The contact thrust on steep pads when ``alpha`` is ``None`` (m/s^2, mass-normalised):
        :data:`ALPHA_NOMINAL` (4, the paper's experiments) by default. A vehicle whose rotors lag
        or sit near their floor in the final pitch-up wants more: the moment a quadrotor can
        produce shrinks with its thrust, and the trackability limit of a replan scales with it
        (``ReplanConfig.snap_thrust_max``). In the realistic simulator (20 ms motor lag; before
        the controller's thrust lead) 6 raised AVP's perches on a wall at 7.5 m from 83 to 92 of
        100 (and from 82 to 94 on 100 seeds not used before); the realistic point of
        ``avp.sim`` (``SimConfig``) flies 6 through ``SimScenario.alpha_nominal``, whose default
        (``None``) keeps the planner's 4 (``docs/simulation.md``).
    alpha_range:
        If given, ``(lo, hi)``: the contact thrust is a decision variable in that range (the
        terminal acceleration is only required to be along ``s3``), as Gao et al., "Adaptive
        Tracking and Perching for Quadrotor in Dynamic Scenarios" do.
    q, t_k, dt:
        Pre-impact band (14): width ``q``, window ``t_k`` before contact sampled every ``dt``.
    band_min_width:
        PAPER mode: floor (m/s^2) on each component's band width; 0 reproduces the paper's
        zero-width rows where a component of ``alpha s3 - g e3`` is zero.
    cone_half_angle, cone_facets:
        CONE mode: tilt cone of ``a + g e3`` about ``s3`` (rad), inner polyhedral approximation.
    min_distance:
        A target closer than this (m) to a start at rest is rejected.
    solver, qp_form, solver_options:
        qpsolvers back-end name (``"daqp"``, ``"proxqp"``, ``"osqp"``...), how the QP is
        passed, and extra keyword arguments merged over avp's per-solver tolerances.
    fov:
        :class:`~avp.camera.FovConfig`: FoV rows (7)-(9), SQP steps and the fallback (16).
    bounds:
        :class:`BoundsPolicy`: certification of the limits, time search, relaxations.
    workspace:
        :class:`Workspace`: perch-plane clearance, ground, speed, half-spaces and spheres,
        certified and never relaxed.
    flip:
        :class:`OverhangFlip`: the thrust turns through the horizontal on overhangs (> 95 deg).
    """

    n_segments: int = 3
    degree: int = 7
    position_cost_order: int = 4
    yaw_cost_order: int = 3
    continuity_order: int = 4
    alpha: float | None = None
    alpha_nominal: float = ALPHA_NOMINAL
    alpha_range: tuple[float, float] | None = None
    q: float = 0.1
    t_k: float = 0.15
    dt: float = 0.01
    pre_impact: PreImpactMode = PreImpactMode.PAPER
    band_min_width: float = 0.1
    cone_half_angle: float = math.radians(15.0)
    cone_facets: int = 8
    contact_velocity: ContactVelocity = field(default_factory=ContactVelocity)
    limits: VehicleLimits = field(default_factory=VehicleLimits)
    time_allocation: TimeAllocation = field(default_factory=TimeAllocation)
    min_distance: float = 0.05
    g: float = GRAVITY
    solver: str = "daqp"
    qp_form: QpForm = QpForm.REDUCED
    solver_options: tuple[tuple[str, Any], ...] = ()
    fov: FovConfig = field(default_factory=FovConfig)
    bounds: BoundsPolicy = field(default_factory=BoundsPolicy)
    workspace: Workspace = field(default_factory=Workspace)
    flip: OverhangFlip = field(default_factory=OverhangFlip)

    def __post_init__(self) -> None:
        for name, lo, hi, hint in (
            ("n_segments", 1, MAX_SEGMENTS, ""),
            ("degree", 4, 20, "(position to jerk are fixed at the start and continuous at the knots: "
                              "continuity_order is at least 3 and below the degree)"),
            ("position_cost_order", 1, None, ""), ("yaw_cost_order", 1, None, ""), ("continuity_order", 3, None,
             "(position to jerk continuous at the knots: the attitude (11) and body rates (22) the "
             "certificates bound within each segment do not jump between them)"),
            ("cone_facets", 3, 64, ""),
        ):
            v.integer(f"config.{name}", getattr(self, name), lo, hi, hint)
        if self.continuity_order >= self.degree:
            raise ConfigError("config.continuity_order", f"must be below the degree ({self.degree})")
        if self.position_cost_order > self.degree or self.yaw_cost_order > self.degree:
            raise ConfigError("config.degree", "must be at least the cost orders")
        if self.degree < 2 * self.position_cost_order - 1:
            raise ConfigError("config.degree", f"must be >= {2 * self.position_cost_order - 1} for a cost of order {self.position_cost_order}")
        if self.alpha is not None:
            object.__setattr__(self, "alpha", v.positive_float("config.alpha", self.alpha))
        object.__setattr__(self, "alpha_nominal", v.positive_float("config.alpha_nominal", self.alpha_nominal))
        object.__setattr__(self, "q", v.nonnegative_float("config.q", self.q))
        v.positive_float("config.t_k", self.t_k)
        v.positive_float("config.dt", self.dt)
        ratio = self.t_k / self.dt  # the band (14) takes round(ratio) samples (a relaxation may turn it on)
        if not (math.isfinite(ratio) and 1 <= round(ratio) <= 1000):
            count = f"{round(ratio)}" if math.isfinite(ratio) and ratio < 1e6 else "too many"
            raise ConfigError("config.dt", f"{self.dt:g} s with t_k = {self.t_k:g} s gives t_k / dt = {ratio:.6g}, "
                              f"{count} samples of the band (14); it needs 1 to 1000: dt in "
                              f"({self.t_k / 1000.5:.4g}, {2 * self.t_k:.4g}) s for this t_k")
        object.__setattr__(self, "band_min_width", v.nonnegative_float("config.band_min_width", self.band_min_width))
        if not 0.0 < v.finite_float("config.cone_half_angle", self.cone_half_angle) < math.pi / 2:
            raise ConfigError("config.cone_half_angle", "must be in (0, pi/2) rad")
        v.positive_float("config.min_distance", self.min_distance)
        v.positive_float("config.g", self.g)
        if not isinstance(self.pre_impact, PreImpactMode):
            raise ConfigError("config.pre_impact", f"must be a PreImpactMode, got {self.pre_impact!r}")
        if not isinstance(self.qp_form, QpForm):
            raise ConfigError("config.qp_form", f"must be a QpForm, got {self.qp_form!r}")
        if not isinstance(self.solver, str):
            raise ConfigError("config.solver", f"must be a qpsolvers solver name, got {self.solver!r}")
        # the one table of back-end facts (that module imports this one)
        from .solve import backend, known_solvers

        known = known_solvers()
        if self.solver not in known:  # a typo; a known back-end not installed here is the SolverError of a plan
            hint = f"did you mean {self.solver.lower()!r}? " if self.solver.lower() in known else ""
            raise ConfigError("config.solver", f"{self.solver!r} is not a qpsolvers back-end; {hint}qpsolvers knows "
                                               f"{', '.join(known)}")
        if self.qp_form is QpForm.FULL and not backend(self.solver).full_form:
            raise ConfigError("config.qp_form", f"QpForm.FULL with '{self.solver}' gives feasible plans far from "
                                                "the optimum (its Hessian is singular in that form); use "
                                                "QpForm.REDUCED (the default) or solver='proxqp' (avp.solve.Backend.full_form)")
        object.__setattr__(self, "solver_options", _solver_options(self.solver_options))
        for name, kind in (("contact_velocity", ContactVelocity), ("limits", VehicleLimits),
                           ("time_allocation", TimeAllocation), ("fov", FovConfig), ("bounds", BoundsPolicy),
                           ("workspace", Workspace), ("flip", OverhangFlip)):
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(f"config.{name}", f"must be an avp.{kind.__name__}, got {getattr(self, name)!r}")
        if not self.limits.accel_max > self.g:  # the hover the planner starts from and the band need it
            raise ConfigError(
                "limits.thrust_max",
                f"thrust_max / mass = {self.limits.accel_max:.3g} m/s^2 is not above g = {self.g:g} m/s^2: this "
                "vehicle cannot hover or climb; check limits.thrust_max (N) and limits.mass (kg)",
            )
        if self.bounds.certify:  # the moving and line planners, which always certify, check it there
            check_body_rate_degree(self.degree, self.limits)
        if self.alpha_range is not None:
            pair = v.sequence("config.alpha_range", self.alpha_range, "two thrusts (lo, hi), m/s^2")
            if len(pair) != 2:
                raise ConfigError("config.alpha_range", f"must be (lo, hi) m/s^2, got {self.alpha_range!r}")
            a_lo, a_hi = (v.finite_float("config.alpha_range", x) for x in pair)
            if not (math.isfinite(a_lo) and math.isfinite(a_hi) and 0.0 < a_lo <= a_hi):
                raise ConfigError("config.alpha_range", f"must be (lo, hi) with 0 < lo <= hi, got {self.alpha_range}")
            object.__setattr__(self, "alpha_range", (a_lo, a_hi))
        if self.flip.thrust is not None and not self.limits.accel_min < self.flip.thrust < self.limits.accel_max:
            raise ConfigError(
                "flip.thrust",
                f"{self.flip.thrust} m/s^2 must lie strictly inside the thrust limits "
                f"({self.limits.accel_min:.2f}, {self.limits.accel_max:.2f}) m/s^2 (limits / mass)",
            )
        if self.alpha is not None and not self.limits.accel_min < self.alpha < self.limits.accel_max:
            raise ConfigError(
                "config.alpha",
                f"contact thrust {self.alpha} m/s^2 must lie strictly inside the thrust limits "
                f"({self.limits.accel_min:.2f}, {self.limits.accel_max:.2f}) m/s^2 (limits / mass): "
                "the bound certificate would fail at contact; change alpha or the limits",
            )

    def contact_alpha(self, incline: float) -> float:
        """The contact thrust ``alpha`` (m/s^2) used for a pad of this ``incline`` (rad): the
        configured value, or with ``alpha=None`` ``max(alpha_nominal, g cos(incline))`` kept
        strictly inside the thrust limits (``ConfigError`` when the limits leave no room)."""
        if self.alpha is not None:
            return float(self.alpha)
        lo, hi = self.limits.accel_min, self.limits.accel_max
        want = max(self.alpha_nominal, self.g * math.cos(incline))
        margin = 0.02 * (hi - lo)
        alpha = min(max(want, lo + margin), hi - margin)
        if alpha < want - 1e-9:
            raise ConfigError(
                "limits.thrust_max",
                f"{hi:.2f} m/s^2 (thrust_max / mass) leaves no contact thrust of at least "
                f"max(alpha_nominal, g cos(incline)) = {want:.2f} m/s^2 for a {math.degrees(incline):.1f} deg "
                "pad; raise the thrust limit, lower config.alpha_nominal or set config.alpha explicitly",
            )
        return alpha

    @property
    def band_samples(self) -> int:
        """Number of band (14) samples, ``round(t_k/dt)`` (``int`` would give 14 for 0.15/0.01)."""
        return int(round(self.t_k / self.dt))

    def changed(self, names: tuple[str, ...]) -> list[str]:
        """The settings among ``names`` (dotted: ``"workspace.body_offset"``) that differ from
        a default ``PlannerConfig()``'s (:func:`_same`). A planner that does not use some
        settings logs these (:data:`avp.line_planner.NOT_USED`, :data:`avp.moving.NOT_USED`).
        Kept per configuration (it is frozen): a replanner asks at every step."""
        cache: dict[tuple[str, ...], list[str]] = self.__dict__.setdefault("_changed", {})
        if names in cache:
            return list(cache[names])
        default = _default_planner_config()

        def value(c: Any, name: str) -> Any:
            for part in name.split("."):
                c = getattr(c, part)
            return c

        cache[names] = [name for name in names if not _same(value(self, name), value(default, name))]
        return list(cache[names])


@lru_cache(maxsize=1)
def _default_planner_config() -> PlannerConfig:
    """The paper-default ``PlannerConfig()``, one frozen object (what :meth:`PlannerConfig.changed`
    compares with, and what a planning call without a configuration plans with)."""
    return PlannerConfig()


def _same(a: Any, b: Any) -> bool:
    """``a == b`` for settings: dataclasses field by field, arrays element by element (the
    camera's ``R_BC``), the rest by ``==``."""
    if a is b:
        return True
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape and bool(np.array_equal(a, b))
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


@v.typed_keywords("replan")
@dataclass(frozen=True)
class ReplanConfig:
    """Replanning policy (module docstring). Defaults measured in closed loop in the realistic
    simulator (``docs/simulation.md``, "Replanning policy"; 90 deg wall and 45 deg slope at 4.5 m
    and 7.5 m, 20 ms motor lag, 3 mm / 1 cm/s odometry noise with drift, 3 % range bias).

    Parameters
    ----------
    latency:
        Time (s) between the odometry sample ``t_rp`` and the switch to the new plan ``t_ex``.
        20 ms: the median replan step measured 8-15 ms on 2 shared cores. With
        :class:`avp.BackgroundReplanner`, keep it above the worker's planning time plus the
        interval at which the loop polls for the plan (a plan adopted after ``t_ex`` is late).
    adapt_latency:
        If true, use ``max(latency, latency_margin * recent median solve time)``.
    latency_margin:
        Safety factor on the measured solve time.
    freeze_horizon:
        No replanning when less than this (s) is left to contact (at least the band window).
        0.25 s: 0.15 s gave identical outcomes (6 seeds, wall at 4.5 / 7.5 m): replans that late
        do not pass the trackability certificate anyway, so the freeze only saves solves.
    deadline:
        A budget (s, wall clock, from the start of the replanning policy of a step; the first
        plan has none) for a replanning step; ``None``: no deadline. A solve after the step's
        first starts only while it, predicted as slow as the first (solve and certificates),
        fits (a ``retime_retries`` retry only while it and the smallest fraction, when the
        order has one, fit), and a static pad's planning call gets the time left
        (:func:`avp.plan_detailed` ``deadline``: no time-search step or refinement round that
        would overrun; the moving-pad and line planners have no budget of their own). When nothing more fits, a certified smallest
        fraction is committed if the step has one, else the committed plan is kept. A solve that
        ends past the deadline, certificates included, ends the step: its plan is committed if
        certified, else the same fallback. Such a plan's switch time ``t_ex`` may have passed
        when the step returns; :meth:`Replanner.reference` then flies it at once (the reason
        says "past the deadline"). Discarding it saved no time and, on a simulated onboard
        computer much slower than the development machine, cost most of the perches
        (``docs/simulation.md``, "The onboard computer's time"). A step cut before its partial
        corrections leaves the rest of its order (the retimed retries still due, then the
        fractions) to the next step that solves, which begins there (its reason says so), not
        with the full correction again; a held step drops it. ``None`` by default, so that a run
        makes the same decisions on any machine (the simulator's figures). With 4 ms, at most
        one step in 11,438 took over 5 ms in the closed loop of avp's model; on rotorpy's
        realistic wall, where a step then has time for one solve, AVP perched about 7 / 10 fewer
        of 100 at 4.5 / 7.5 m than without a deadline (``docs/performance.md``, 2026-12-04).
    measured_orders:
        When re-anchoring: derivative orders taken from odometry (2: position and velocity, yaw
        and yaw rate); higher orders come from the committed plan, so commands stay continuous (6).
    warm_start:
        Pass the committed plan as initial guess to back-ends that accept one (``warm_start``
        in :data:`avp.solve.BACKENDS`; DAQP takes none). A static pad only: the moving and line
        planners take no guess.
    search_on_replan:
        Let replans run the duration search and relaxations of ``config.bounds``. Off: a replan
        keeps the committed contact time (in closed loop the search made the contact time drift
        from 2.5 s to 20 s at 7.5 m and cost up to 55 solves per step).
    anchor_position, anchor_velocity:
        Tracking error (m, m/s) between odometry and the committed reference below which a
        replan starts from the committed plan's own state (anchored), above which it re-anchors
        on odometry. 0.15 m / 0.5 m/s: above the tracking error seen with certified plans and
        20 ms motor lag (up to 8 cm at the end of a wall perch), far above the 3 mm / 1 cm/s
        odometry noise, so noise never re-anchors. With anchoring, exact-estimate runs hold the
        first plan and match one-shot exactly (100 % vs 100 % over 15 seeds x 6 conditions);
        a closed-loop report from an independent simulator measured 1/5 such perches when every
        replan re-anchored on noisy odometry.
    target_tolerance:
        Change (m) of the estimated pad centre (and ``target_tolerance`` rad of its normal)
        below which, when anchored, the step holds the committed plan without solving (a turn
        of the pad about its normal is not a change: the committed contact yaw stays). 5 mm:
        a sixth of the 3 cm plane tolerance of a perch (chosen, not tuned; with a perfect
        estimate every step holds, which is what makes AVP equal one-shot there). A static pad
        only: a moving pad's estimate moves it at every step (:class:`~avp.moving.MovingReplanner`
        never holds), a line has its own tolerances (:class:`~avp.line_replan.LineReplanner`).
    reach_acceleration:
        Budget (m/s^2) on moving the contact point: at most ``0.5 reach_acceleration T^2`` with
        ``T`` the time left. 6 m/s^2: chosen (not tuned), about 60 % of the 9.8 m/s^2 thrust
        margin above hover; in the measured runs the trackability certificate, not this budget,
        was what stopped late corrections (the budget binds early, on far, noisy estimates).
        A static pad only, as ``partial_fractions``: a moving pad's or a line's correction is
        full or none.
    partial_fractions:
        Fractions of the (budgeted) correction, strictly decreasing. Tried in the order: the
        first, the last, and only if the last certifies the ones between, in order; the first
        of those that certifies is committed, else the last. So when the smallest certifies the
        largest certifying fraction is committed; when it does not, none is (a larger one that
        would have certified is not tried). Only the full correction is tried when the estimated
        normal turned by 90 deg or more from the committed one (a flipped normal): a blend of
        the two frames barely turns below half the correction and flips past it. A step that
        cannot correct at all costs two solves
        (plus the failed ``retime_retries``), a committed fraction between one solve more than in
        plain order. Over 168 closed-loop
        runs against plain order: the same number of perches (142), the step p99 at 6.0 instead
        of 8.4 ms. ``(1, 0.5, 0.25, 0.125)``: with ``(1, 0.5, 0.25)`` 1/6 (4.5 m) and
        4/6 (7.5 m) wall perches succeeded, with the extra 1/8 step 2/6 and 3/6 (6 seeds each;
        repeated small commits accumulate).
    partial_min_correction:
        A latency knob, off (0) by default. In an anchored step, a fraction after the first of
        ``partial_fractions`` is tried only when it moves the goal by more than this (m for the
        pad centre, rad for its normal, as ``target_tolerance``); the first is always tried, and
        a step that re-anchors on odometry tries every fraction (its plan also corrects the
        tracking). A static pad only, as ``partial_fractions`` (a moving pad, a line and a
        flipped normal try the full correction alone). The steps that make four to six solves are late, small
        corrections (4-14 mm, 0.15-0.5 deg, measured) whose full correction fails a certificate
        while a fraction of a few mm certifies. At ``target_tolerance`` (5 mm) the 30 Hz loop of
        avp's model (``benchmarks/bench_replan.py --seeds 6 --gc-freeze``) had a step p99 of
        3.1-3.3 instead of 4.3-4.5 ms and 5-6 instead of 17-23 steps over 5 ms of about 2,450
        (three runs each). The price: a few mm still move the contact. On
        rotorpy's realistic wall (seeds 0-199, 4.5 and 7.5 m) AVP perched 6 fewer of 400 (the
        four of seeds 100-199 at 4.5 m ended 3.0-3.2 cm off the pad's plane, where the fractions
        had left them 2.5-2.9 cm, inside the 3 cm tolerance); on avp's model 2 fewer of 600
        (walls and slopes). ``docs/performance.md`` has the figures.
    reach_tolerance:
        Distance (m) between the committed contact point and the latest estimate above which a
        step without a full correction reports ``CANNOT_REACH``. 0.05 m: half the in-plane
        success radius. For a moving pad, the distance to the pad the estimate predicts at the
        committed contact time; for a line, from the committed grasp point to the estimated
        line (:mod:`avp.line_replan`).
    reach_angle_tolerance:
        Angle (rad) between the committed pad's normal and the latest estimate's above which a
        step without a full correction reports ``CANNOT_REACH`` as for ``reach_tolerance``:
        the plan would touch the surface that far from square. 10 deg: the simulator's perch
        criterion (``b3`` within 10 deg of ``s3``); its estimates turn by at most 6.3 deg
        (wall and slope at 4.5 and 7.5 m, seeds 0-2). For a line, the angle between the
        committed grasped piece and the estimate's piece at the grasp point.
    snap_max, snap_thrust_max:
        Trackability limits certified on every committed replan (:mod:`avp.trackability`;
        ``inf`` skips one): ``|s| < snap_max`` (m/s^4) and ``|s| < snap_thrust_max |a + g e3|``
        (1/s^2, an angular-acceleration scale). The first plan is certified for the actuator
        bounds and its own trackability figures are recorded; the limits used for replans are
        ``max(limit, 1.05 x the first plan's peak)``, so a replan never demands more than the
        worse of the limit and the plan the user accepted. 600 m/s^4 and 45 1/s^2: first plans
        from hover at 4.5-7.5 m peak at 120-240 m/s^4 and 18-31 1/s^2 (1.5 m: 320-740, 67-97);
        the late replans that lost the attitude (40-80 deg at contact with 20 ms motor lag, the
        rotors at their floor during the pitch-up) carried 75-90 1/s^2.
    retime_normal:
        Move the contact time with the normal component ``dn`` of a target correction:
        the remaining time becomes ``T - dn / v_n`` (``v_n`` the contact normal speed, at most
        ``retime_fraction`` of ``T`` either way), so a pad found deeper is reached later at the same
        approach, instead of by a steeper plan. On: at 4.5 m on a wall, late normal corrections of
        1.5-4 cm were otherwise uncertifiable and the 2 m/s slide turned each cm of normal error into
        about 7 cm along the pad. Off by default: measured worse (0/6 vs 1/6 at 4.5 m and 0/6 vs
        4/6 at 7.5 m on a wall), since early corrections from far, noisy estimates moved the
        contact time by tenths of a second. A static pad only: the moving and line replanners
        keep the committed contact time.
    retime_fraction:
        Cap on the retiming, as a fraction of the time left.
    retime_retries:
        Factors on the time left with which the full correction is solved again, in order, when
        its plan fails only a certificate (the trackability certificate or the actuator bounds),
        before any partial fraction; the first plan that certifies is committed (its contact
        time moves by the factor). Those certificates are not monotone in the time left: a late
        correction that fails at the nominal time often certifies a few per cent either side,
        while a longer time (1.15, 1.3: snap scales as ``T^-4``) did not help. ``()``: off.
        ``(0.97, 1.03)``: AVP on rotorpy's wall at 4.5 / 7.5 m 51 / 49 of 60 against 49 / 46
        (seeds 0-59) and 81 / 81 of 100 against 77 / 77 (seeds 100-199, not used to choose); on
        avp's model (seeds 0-99) 97 / 92 of 100 against 94 / 89. 0.5-0.7 commits per run are
        retimed, for 24 % more planning calls per run (most retries fail). Of the retimed
        commits with ``(0.97, 1.03, 0.94, 1.06)`` (avp's model, 80 wall runs) 39 took 0.97, 15
        took 1.03, one 0.94 and none 1.06; that list perched 51 / 50 and 82 / 81 for 50-60 % more
        calls. Retrying the partial fractions too gained one or two seeds more for 1.9 times the
        default's calls. Only for a static pad: a subclass with its own target model (a moving
        pad, a line) keeps the committed contact time.
    retime_backoff:
        After a step whose ``retime_retries`` all ran and failed and that committed nothing, the
        following steps make none until a step commits a plan (:attr:`ReplanStep.committed
        <avp.replan.ReplanStep.committed>`, a full or partial correction, also one reported as
        ``CANNOT_REACH``): the nominal time and the partial fractions only, and the step's
        reason says so. Retries a ``deadline`` spread over several steps start it once the
        last of them has run and failed; retries it cut and never made do not. With nothing
        committed, the next step solves nearly the same problem (the same committed plan, an
        estimate and a time left 33 ms on), and its retries fail again: in
        ``benchmarks/bench_replan.py --seeds 28`` without the backoff, of the steps after one
        whose retries all failed and that committed nothing, 119 retried and failed and 1
        certified a retry; after a partial commit 45 and 1; after any other step 72 and 61. The
        backoff took 108 of the 274 steps over 5 ms there. Measured with and without
        (``--no-retime-backoff``), AVP on the realistic wall (90 deg, 4.5 / 7.5 m): rotorpy 96 /
        92 of 100 both (seeds 0-99) and 92 / 94 both (seeds 100-199), avp's model 96 / 94 both
        (seeds 0-99); planning calls per run on rotorpy 34.0 / 41.1 against 37.4 / 46.5 (seeds
        0-59). A backoff that also held through partial commits lost a perch there (seed 37 at
        4.5 m: after three partial commits a retry certified the full correction). ``False``:
        retries at every step.
    retime_min_time:
        Time left (s) below which a replan makes no ``retime_retries``. Logged on the realistic
        wall (``SimConfig``, 90 deg, 4.5 and 7.5 m, AVP, the retries everywhere): on avp's
        model (seeds 0-99) 224 retried corrections with 0.25-0.3 s left, none committed; 1 of
        227 at 0.3-0.35 s (the earliest at 0.31 s), 7 of 420 at 0.35-0.45 s, 57 of 289 at
        0.45-0.6 s; on rotorpy (seeds 0-29) 0 of 151 below 0.35 s, the earliest at 0.385 s. Late
        corrections need a snap of order ``delta / T^4`` that a few per cent of time rarely
        brings under the limit. 0.3 s: no certified retry is lost in those 260 runs and the
        same 200 avp runs make the same decisions with 432 fewer solves (8539 against 8971);
        0.45 s lost 8 committed retries and one perch of 200 (wall, 7.5 m).
    allow_relaxed:
        Commit plans the planner obtained by relaxing something (``result.relaxations``, status
        ``SOLVED_RELAXED``). Off: a relaxed plan moves the contact velocity or band.
    keep_knots:
        Lay a replan's segments on the committed plan's own knots after ``t_ex`` (the longest
        piece halved until there are ``n_segments``) instead of ``n_segments`` equal pieces of
        the time left (a static pad only: :class:`~avp.moving.MovingReplanner` and
        :class:`~avp.line_replan.LineReplanner` use the total alone). The committed remainder
        is then a spline of the replan's layout: a replan to the committed target 0.3 s into a
        wall perch stays within 0.2 mm of the committed plan where equal pieces move it by 1 cm,
        and a small correction no longer fails the trackability certificate only because the
        layout moved (on rotorpy's wall a replan to the same target peaked at 46-48 1/s^2
        against the committed 44.1, over the limit in force, 45). Not where a piece is halved:
        continuity stops at snap, so the halves may leave the committed polynomial (8 mm at
        0.9 s, as with equal pieces; 0.9 mm without the halving). Off by default: its gain was
        within noise (rotorpy's wall, seeds 0-59, with the drag-aware FoV rows: 45 / 46 of 60
        at 4.5 / 7.5 m against 42 / 42; avp's model, seeds 0-99: 91 / 91 against 90 / 92, one
        fewer at 7.5 m; ``benchmarks/bench_replan.py --seeds 28``: 143 of 168 against 140), and
        every replan then has its own duration ratios, so the elimination cache misses and a
        solving step costs 2.42 instead of 1.51 ms (median; p99 of all steps 4.29 against
        3.57 ms, 70 steps over 5 ms against 39).
    keep_knots_min:
        With ``keep_knots``: when the committed plan's next knot comes within this share of an
        equal segment (``(t_f - t_ex) / n_segments``) after ``t_ex``, the switch to the new plan
        moves to that knot instead. A shorter first segment would be ill-conditioned (first
        pieces of 2-20 ms before a 0.4-0.8 s one made the QP infeasible), and merging it into the
        next loses the knot (measured: 44.1 -> 45.4 1/s^2 for a replan to the same target).
        0.05: at most 5 % of a segment (a few ms near contact) later than ``t_ex``; at most 0.5.
    """

    latency: float = 0.02
    adapt_latency: bool = False
    latency_margin: float = 1.5
    freeze_horizon: float = 0.25
    deadline: float | None = None
    measured_orders: int = 2
    warm_start: bool = True
    search_on_replan: bool = False
    anchor_position: float = 0.15
    anchor_velocity: float = 0.5
    target_tolerance: float = 0.005
    reach_acceleration: float = 6.0
    partial_fractions: tuple[float, ...] = (1.0, 0.5, 0.25, 0.125)
    partial_min_correction: float = 0.0
    reach_tolerance: float = 0.05
    reach_angle_tolerance: float = math.radians(10.0)
    snap_max: float = 600.0
    snap_thrust_max: float = 45.0
    retime_normal: bool = False
    retime_fraction: float = 0.3
    retime_retries: tuple[float, ...] = (0.97, 1.03)
    retime_min_time: float = 0.3
    retime_backoff: bool = True
    allow_relaxed: bool = False
    keep_knots: bool = False
    keep_knots_min: float = 0.05

    def __post_init__(self) -> None:
        v.flags("replan", self)
        v.positive_float("replan.latency", self.latency)
        v.positive_float("replan.latency_margin", self.latency_margin)
        v.positive_float("replan.freeze_horizon", self.freeze_horizon)
        if self.deadline is not None:
            v.positive_float("replan.deadline", self.deadline)
        v.integer("replan.measured_orders", self.measured_orders, 0, 5, "(0: all orders from the plan)")
        for name in ("anchor_position", "anchor_velocity", "target_tolerance"):
            val = v.finite_float(f"replan.{name}", getattr(self, name))
            if val < 0:
                raise ConfigError(f"replan.{name}", f"must be >= 0 (0: never anchor / never hold), got {val}")
        object.__setattr__(self, "partial_min_correction",
                           v.nonnegative_float("replan.partial_min_correction", self.partial_min_correction))
        v.positive_float("replan.reach_acceleration", self.reach_acceleration, allow_inf=True)
        v.positive_float("replan.reach_tolerance", self.reach_tolerance)
        if not 0.0 < v.finite_float("replan.reach_angle_tolerance", self.reach_angle_tolerance) <= math.pi:
            raise ConfigError("replan.reach_angle_tolerance", f"must be in (0, pi] rad, got {self.reach_angle_tolerance}")
        kmin = v.finite_float("replan.keep_knots_min", self.keep_knots_min)
        if not 0.0 < kmin <= 0.5:
            raise ConfigError("replan.keep_knots_min",
                              f"must be in (0, 0.5] (a share of an equal segment; 0 lets a first segment of a few ms "
                              f"make the QP infeasible), got {kmin}")
        v.positive_float("replan.snap_max", self.snap_max, allow_inf=True)
        v.positive_float("replan.snap_thrust_max", self.snap_thrust_max, allow_inf=True)
        fr = tuple(v.finite_float("replan.partial_fractions", f)
                   for f in v.sequence("replan.partial_fractions", self.partial_fractions, "fractions in (0, 1]"))
        if not fr or any(not 0.0 < f <= 1.0 for f in fr):
            raise ConfigError("replan.partial_fractions", f"need fractions in (0, 1], got {self.partial_fractions!r}")
        if any(b >= a for a, b in itertools.pairwise(fr)):
            raise ConfigError("replan.partial_fractions",
                              f"must be strictly decreasing (largest first), got {self.partial_fractions!r}")
        object.__setattr__(self, "partial_fractions", fr)
        retries = v.sequence("replan.retime_retries", self.retime_retries, "factors on the time left")
        rr = tuple(v.nonnegative_float(f"replan.retime_retries[{i}]", f) for i, f in enumerate(retries))
        for i, f in enumerate(rr):
            if not 0.5 <= f <= 2.0 or f == 1.0:
                raise ConfigError(f"replan.retime_retries[{i}]",
                                  f"need a factor in [0.5, 2] other than 1 (the nominal time is always tried "
                                  f"first), got {f!r}; () turns the retries off")
        if len(set(rr)) != len(rr):
            raise ConfigError("replan.retime_retries",
                              f"each factor once (a repeated one solves the same problem again), got {rr!r}")
        object.__setattr__(self, "retime_retries", rr)
        object.__setattr__(self, "retime_min_time", v.nonnegative_float("replan.retime_min_time",
                                                                        self.retime_min_time))
        fraction = v.nonnegative_float("replan.retime_fraction", self.retime_fraction)
        if fraction >= 1.0:
            raise ConfigError("replan.retime_fraction", f"must be in [0, 1) (a share of the time left), got {fraction}")
        object.__setattr__(self, "retime_fraction", fraction)
