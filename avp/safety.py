"""Workspace safety: clearance from the perch plane and the ground, speed, extra half-spaces and
keep-out spheres, as QP rows on samples and as certificates of the exact polynomials.

Each limit of :class:`~avp.config.Workspace` is a region the centre of mass (or, for the speed,
the velocity) must stay in. The planner puts linear rows on samples into the QP
(:func:`workspace_blocks`), certifies the solution with the Rust kernels
(``avp._avp_rust.certify_halfspace`` / ``certify_sphere_outside`` / ``certify_speed``), and,
where a limit is proven violated, re-solves with denser, tightened rows around the violation
(:func:`refinement_blocks`). Only a plan whose every region is proven (:attr:`SafetyReport.
certified`) is returned as solved; the time search and relaxations never remove these rows.

The perch plane (and any other plane the contact point lies on) is *touched* at contact, so its
polynomial has a root at ``t_f``; the kernel divides it out and certifies the quotient together
with the approach direction (``docs/bounds.md``, "Workspace certificates").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from . import _avp_rust
from ._typing import Array
from .bounds import Certificate
from .config import PlannerConfig, Workspace
from .errors import ConfigError
from .qp.assemble import ConstraintBlock
from .qp.layout import DecisionLayout, layout_for
from .qp.rows import vector_rows
from .trajectory import Trajectory
from .types import PerchTarget, State

__all__ = [
    "RESIDUAL_TOL",
    "Region",
    "RegionCheck",
    "SafetyReport",
    "certify_workspace",
    "check_endpoints",
    "check_start",
    "contact_position",
    "outside",
    "refinement_blocks",
    "regions_for",
    "workspace_blocks",
]


RESIDUAL_TOL = 1e-9
"""Largest certified contact residual (m) accepted on a touched plane: the position may be this
far beyond the plane at contact, where the equalities hold to rounding (about 1e-15 m)."""

TOUCH_TOL = 1e-9
"""A plane lies through the contact point when the contact point is within this (m) of it."""

_CODES = (Certificate.WITHIN, Certificate.VIOLATED, Certificate.UNKNOWN)


@dataclass(frozen=True)
class Region:
    """One limit: ``kind`` is ``"half-space"`` (``normal . p > offset``), ``"sphere"``
    (``|p - center| > radius``) or ``"speed"`` (``|v| < radius``). ``touches`` marks a plane
    through the contact point (certified with the root at ``t_f`` divided out)."""

    name: str
    kind: str
    normal: Array
    offset: float
    touches: bool = False


def contact_position(target: PerchTarget, workspace: Workspace) -> Array:
    """Centre of mass at contact: the pad centre plus ``body_offset`` along ``s3``."""
    return np.asarray(target.point + workspace.body_offset * target.s3, dtype=np.float64)


_LAST_REGIONS: tuple[PerchTarget, Workspace, tuple[Region, ...]] | None = None
"""The last :func:`regions_for` call, held by reference (one planning call asks for the same
regions three times). Both arguments are frozen dataclasses whose arrays the constructors make
read-only copies of, and the regions' own arrays are read-only copies."""


def regions_for(target: PerchTarget, workspace: Workspace) -> tuple[Region, ...]:
    """The regions of ``workspace`` for a perch on ``target``, in a fixed order: perch plane,
    ground, half-spaces, spheres, speed."""
    global _LAST_REGIONS
    last = _LAST_REGIONS
    if last is not None and last[0] is target and last[1] is workspace:
        return last[2]
    regions = _regions_for(target, workspace)
    _LAST_REGIONS = (target, workspace, regions)
    return regions


def _regions_for(target: PerchTarget, workspace: Workspace) -> tuple[Region, ...]:
    p_c = contact_position(target, workspace)
    planes: list[tuple[str, Array, float]] = []
    if workspace.perch_clearance:
        planes.append(("perch plane", target.s3, float(target.s3 @ p_c)))
    if workspace.ground_z is not None:
        planes.append(("ground", np.array([0.0, 0.0, 1.0]), float(workspace.ground_z)))
    planes += [(f"half-space {k}", h.normal, h.offset) for k, h in enumerate(workspace.half_spaces)]
    out = [Region(name, "half-space", _frozen(n), d, abs(float(n @ p_c) - d) <= TOUCH_TOL) for name, n, d in planes]
    out += [Region(f"sphere {k}", "sphere", _frozen(s.center), float(s.radius)) for k, s in enumerate(workspace.spheres)]
    if math.isfinite(workspace.max_speed):
        out.append(Region("max speed", "speed", _frozen(np.zeros(3)), float(workspace.max_speed)))
    return tuple(out)


def _frozen(v: Array) -> Array:
    """A read-only contiguous copy (the regions are shared by later calls, :func:`regions_for`;
    the caller's own arrays are left as they are)."""
    out = np.array(v, dtype=np.float64, order="C")
    out.setflags(write=False)
    return out


def check_endpoints(state: State, target: PerchTarget, config: PlannerConfig) -> None:
    """Rejects a start or a contact point outside the workspace, and a requested contact speed
    at or above ``max_speed`` (:class:`ConfigError`)."""
    workspace = config.workspace
    wanted = config.contact_velocity.components(target.incline)
    if math.isfinite(workspace.max_speed):
        known = math.sqrt(sum(x * x for x in wanted if x is not None))
        if known >= workspace.max_speed:
            raise ConfigError("workspace.max_speed", f"{workspace.max_speed} m/s is not above the requested "
                              f"contact speed ({known:.3f} m/s); raise it or ask for a slower contact")
    _check_points(state, contact_position(target, workspace), regions_for(target, workspace))


def check_start(state: State, pad: PerchTarget, workspace: Workspace, *, contact: bool) -> None:
    """:func:`check_endpoints` for a moving pad, whose contact point is not known before its
    duration: the start position and speed against the workspace limits other than the perch
    plane (which moves with the pad), and with ``contact`` (a pad that does not move) the
    contact point on ``pad`` too (:class:`ConfigError`)."""
    static = replace(workspace, perch_clearance=False)
    _check_points(state, contact_position(pad, static) if contact else None, regions_for(pad, static))


def _check_points(state: State, p_c: Array | None, regions: tuple[Region, ...]) -> None:
    """The start (and the contact point ``p_c`` unless ``None``) against ``regions``."""
    points: tuple[tuple[str, Array, bool], ...] = (("state.position", state.position, True),)
    if p_c is not None:
        points += (("target.point", p_c, False),)
    for r in regions:
        if r.kind == "speed":
            if float(np.linalg.norm(state.velocity)) >= r.offset:
                raise ConfigError("state.velocity", f"speed {np.linalg.norm(state.velocity):.3f} m/s is not below "
                                  f"workspace.max_speed ({r.offset} m/s); raise the limit or start slower")
            continue
        for label, p, strict in points:
            gap = outside(r, p, strict)
            if gap is None:
                continue
            if r.kind == "half-space":
                where = "on or behind" if strict else "behind"
                what = "the pad's outward side (s3)" if r.name == "perch plane" else "the allowed side"
            else:
                where, what = "inside", "outside the keep-out sphere"
            fix = ("start on the side the pad's normal s3 points to (or check the normal's sign)"
                   if r.name == "perch plane" and label == "state.position"
                   else f"move it to {what} or change workspace limits")
            raise ConfigError(label, f"lies {where} the workspace limit '{r.name}' (margin {gap:.4g} m); {fix}")


def outside(region: Region, p: Array, strict: bool) -> float | None:
    """The margin (m) of point ``p`` when it is outside ``region`` (a half-space or a sphere;
    ``strict``: on the plane counts as outside, as for a start), else ``None``."""
    if region.kind == "half-space":
        gap = float(region.normal @ p) - region.offset
        return gap if (gap <= TOUCH_TOL if strict else gap < -TOUCH_TOL) else None
    gap = float(np.linalg.norm(p - region.normal)) - region.offset
    return gap if gap <= 0.0 else None


@dataclass(frozen=True, kw_only=True)
class RegionCheck:
    """Certificate of one :class:`Region` on every segment.

    ``residual`` bounds (m) how far beyond a touched plane the position may be near contact
    (0 for regions not touched); ``touch_order`` is the multiplicity of the root at ``t_f``
    divided out (0 when not touched).
    """

    region: Region
    verdicts: tuple[Certificate, ...]
    times: tuple[float, ...]
    residual: float = 0.0
    touch_order: int = 0

    @property
    def certified(self) -> bool:
        return all(v is Certificate.WITHIN for v in self.verdicts) and self.residual <= RESIDUAL_TOL

    @property
    def violation_times(self) -> list[float]:
        return [t for v, t in zip(self.verdicts, self.times, strict=True) if v is Certificate.VIOLATED]

    def __str__(self) -> str:
        state = "certified" if self.certified else "NOT certified"
        cells = ", ".join(v.value for v in self.verdicts)
        extra = f", contact residual {self.residual:.1e} m (root order {self.touch_order})" if self.touch_order else ""
        when = "".join(f"; violated near t = {t:.4g} s" for t in self.violation_times)
        return f"{self.region.name}: {state} ({cells}{extra}){when}"


@dataclass(frozen=True, kw_only=True)
class SafetyReport:
    """Per-region certificates of a trajectory (:func:`certify_workspace`)."""

    checks: tuple[RegionCheck, ...]

    @property
    def certified(self) -> bool:
        """Every region proven on every segment."""
        return all(c.certified for c in self.checks)

    @property
    def failed(self) -> list[str]:
        """Names of the regions not proven."""
        return [c.region.name for c in self.checks if not c.certified]

    def summary(self) -> str:
        head = "certified" if self.certified else "NOT certified: " + ", ".join(self.failed)
        return "\n".join([f"workspace certificate: {head}"] + [f"  {c}" for c in self.checks])

    def __str__(self) -> str:
        return self.summary()


def _touch_order(traj: Trajectory, normal: Array) -> int:
    """Multiplicity of the root at ``t_f`` to divide out: 1 when the contact velocity goes into
    the plane, 2 when it is tangential (the acceleration must then point out of the plane)."""
    v_n = float(normal @ traj._derivatives_rel(np.array([traj.duration]), [1])[0, 0, :3])  # traj(traj.tf, 1)
    return 1 if v_n < -TOUCH_TOL else 2


def certify_workspace(traj: Trajectory, target: PerchTarget, workspace: Workspace) -> SafetyReport:
    """Certifies every region of ``workspace`` on every segment of ``traj`` (Rust, exact
    fallback: a "within" verdict is never wrong), on the plan's exact segment durations
    (:attr:`~avp.trajectory.Trajectory.knots_rel`); violation times are on its clock."""
    c, k, t0 = traj.coefficients, traj.knots_rel, traj.t0
    checks = []
    for r in regions_for(target, workspace):
        order = 0
        if r.kind == "half-space":
            order = _touch_order(traj, r.normal) if r.touches else 0
            codes, times, residual = _avp_rust.certify_halfspace(c, k, r.normal, r.offset, order)
        elif r.kind == "sphere":
            codes, times, residual = _avp_rust.certify_sphere_outside(c, k, r.normal, r.offset)
        else:
            codes, times, residual = _avp_rust.certify_speed(c, k, r.offset)
        times = times + t0 if t0 else times
        checks.append(RegionCheck(region=r, verdicts=tuple(map(_CODES.__getitem__, codes.tolist())), times=tuple(times.tolist()), residual=float(residual), touch_order=order))
    return SafetyReport(checks=tuple(checks))


def _sample_times(knots_rel: Array, per_segment: int) -> Array:
    """``per_segment`` interior-and-end samples per segment, without the start (fixed by the
    initial state) and without ``t_f`` (fixed by the contact equalities)."""
    start = knots_rel[:-1]
    t = (start[:, None] + (knots_rel[1:] - start)[:, None] * _grid_fractions(per_segment)[None, :]).ravel()
    return np.asarray(t[t < knots_rel[-1] - 1e-12], dtype=np.float64)


@lru_cache(maxsize=32)
def _grid_fractions(per_segment: int) -> Array:
    """``u = 1/per_segment, ..., 1`` of :func:`_sample_times`, read-only."""
    u = np.arange(1, per_segment + 1) / per_segment
    u.setflags(write=False)
    return u


@lru_cache(maxsize=32)
def _grid_position_rows(n_segments: int, degree: int, per_segment: int) -> Array:
    """Position rows ``(m, 3, n_variables)`` at the sample grid of :func:`_sample_times`: they
    depend on the normalised time ``u`` alone, not on the durations (position is order 0). A
    sample on an interior knot is taken at the start of the next segment (``u = 0``), where
    :meth:`~avp.qp.layout.DecisionLayout.locate` puts a time equal to the knot; read-only."""
    layout = layout_for(n_segments, degree)
    seg_u = [(i + 1, 0.0) if j == per_segment else (i, j / per_segment)
             for i in range(n_segments) for j in range(1, per_segment + 1)
             if not (j == per_segment and i == n_segments - 1)]  # t_f: fixed by the contact rows
    rows = np.zeros((len(seg_u), 3, layout.n_variables))
    n_c = layout.n_coeffs
    for k, (seg, u) in enumerate(seg_u):
        local = layout.basis(0, u)
        for axis in range(3):
            start = layout.start(axis, seg)
            rows[k, axis, start:start + n_c] = local
    rows.setflags(write=False)
    return rows


def _position_rows(layout: DecisionLayout, knots_rel: Array, times: Array, per_segment: int | None) -> Array:
    """Position rows at ``times``; from the cached grid rows when ``times`` is the
    ``per_segment`` grid of :func:`_sample_times`."""
    if per_segment is not None and times.size == layout.n_segments * per_segment - 1:
        return _grid_position_rows(layout.n_segments, layout.degree, per_segment)
    return vector_rows(layout, knots_rel, 0, times)


_PLANE_BLOCKS: dict[tuple[object, ...], tuple[Array, ConstraintBlock]] = {}
"""Plane blocks on read-only position rows that own their data (the cached grid rows,
:func:`_grid_position_rows`), by the rows' identity and the plane's exact bits; each entry keeps
its rows alive, so an id is not reused while it is here. The grid rows do not depend on the
durations: a plane that stays put (the ground) has the same block at every replan."""


def _plane_block(name: str, P: Array, normal: Array, offset: Array | float) -> ConstraintBlock:
    """``normal . p(t_j) >= offset`` with ``P`` the position rows at the ``t_j``; shared
    (read-only) for the cached grid rows and a constant offset (:data:`_PLANE_BLOCKS`)."""
    if not (isinstance(offset, float) and not P.flags.writeable and P.base is None):
        return _new_plane_block(name, P, normal, offset)
    key = (name, id(P), normal.tobytes(), offset.hex())  # exact bits (-0.0 is not 0.0)
    hit = _PLANE_BLOCKS.get(key)
    if hit is not None and hit[0] is P:
        return hit[1]
    block = _new_plane_block(name, P, normal, offset)
    for arr in (block.matrix, block.lower, block.upper):
        arr.setflags(write=False)
    if len(_PLANE_BLOCKS) >= 64:
        _PLANE_BLOCKS.clear()
    _PLANE_BLOCKS[key] = (P, block)
    return block


def _new_plane_block(name: str, P: Array, normal: Array, offset: Array | float) -> ConstraintBlock:
    """:func:`_plane_block`, built."""
    # one product and sum per axis (a position row has one axis's columns: the same values as
    # the contraction over the axes, without einsum's dispatch)
    G = normal[0] * P[:, 0, :] + normal[1] * P[:, 1, :] + normal[2] * P[:, 2, :]
    m = P.shape[0]
    lower = np.full(m, offset, dtype=float) if isinstance(offset, float) or np.ndim(offset) == 0 \
        else np.broadcast_to(np.asarray(offset, dtype=float), (m,)).copy()
    return ConstraintBlock(name, G, lower, np.full(m, np.inf))


def workspace_blocks(
    layout: DecisionLayout, knots_rel: Array, state: State, target: PerchTarget, config: PlannerConfig
) -> tuple[ConstraintBlock, ...]:
    """Initial QP rows of every workspace limit on ``samples_per_segment`` samples per segment:
    planes as they are, spheres linearised on the straight line from the start to the contact
    point (the tangent plane at the nearest point of the ball, a sufficient condition). The speed
    gets rows only by refinement (:func:`refinement_blocks`)."""
    ws = config.workspace
    if not ws.active:
        return ()
    times = _sample_times(knots_rel, ws.samples_per_segment)
    if times.size == 0:
        return ()
    blocks = []
    P = _position_rows(layout, knots_rel, times, ws.samples_per_segment)
    line: Array | None = None  # the straight line from the start to the contact point at the samples
    for r in regions_for(target, ws):
        if r.kind == "half-space":
            blocks.append(_plane_block(f"workspace: {r.name}", P, r.normal, r.offset))
        elif r.kind == "sphere":
            if line is None:
                p0, p_c = state.position, contact_position(target, ws)
                line = p0[None, :] + (times / knots_rel[-1])[:, None] * (p_c - p0)[None, :]
            blocks.append(_sphere_block(f"workspace: {r.name}", P, r, line, 0.0))
    return tuple(blocks)


def _sphere_block(name: str, P: Array, r: Region, points: Array, margin: float) -> ConstraintBlock:
    """``n_j . p(t_j) >= n_j . c + radius + margin`` with ``n_j`` from the centre to ``points``
    and ``P`` the position rows at the ``t_j``."""
    d = points - r.normal[None, :]
    norm = np.linalg.norm(d, axis=1)
    d = np.where(norm[:, None] > 1e-9, d / np.maximum(norm, 1e-300)[:, None], np.array([0.0, 0.0, 1.0]))
    G = np.einsum("mi,min->mn", d, P)
    lower = d @ r.normal + r.offset + margin
    return ConstraintBlock(name, G, lower, np.full(P.shape[0], np.inf))


def _around(check: RegionCheck, knots_rel: Array, t0: float) -> Array:
    """9 samples within 20 % of a segment around each proven violation of ``check`` (around
    contact when it has none), relative to the plan start and strictly inside ``(0, t_f)``."""
    T_seg = np.diff(knots_rel)
    tf_rel = float(knots_rel[-1])
    local: list[Array] = []
    for t_abs in check.violation_times or [t0 + tf_rel]:
        t = t_abs - t0
        seg = int(np.clip(np.searchsorted(knots_rel, t, side="right") - 1, 0, T_seg.size - 1))
        h = 0.2 * float(T_seg[seg])
        local.append(np.linspace(t - h, t + h, 9))
    return np.unique(np.clip(np.concatenate(local), 1e-6 * tf_rel, tf_rel * (1 - 1e-6)))


def refinement_blocks(
    layout: DecisionLayout,
    knots_rel: Array,
    traj: Trajectory,
    report: SafetyReport,
    round_index: int,
    config: PlannerConfig,
) -> tuple[ConstraintBlock, ...]:
    """Rows added after a failed certificate: dense samples around each violation, tightened
    by ``refinement_margin * round_index`` (tapered to zero at contact on touched planes);
    spheres re-linearised on the solution; the speed cut by the tangent plane of the speed
    ball at the solution's velocity wherever it exceeds 80 % of the limit."""
    ws = config.workspace
    tf_rel = float(knots_rel[-1])
    t0 = traj.t0
    margin = ws.refinement_margin * round_index
    out: list[ConstraintBlock] = []
    for check in report.checks:
        if check.certified:
            continue
        r = check.region
        if r.kind == "speed":
            times = _sample_times(knots_rel, 4 * ws.samples_per_segment)
            v = traj(t0 + times, 1)
            speed = np.linalg.norm(v, axis=1)
            keep = speed > 0.8 * r.offset
            if not np.any(keep):
                continue
            d = v[keep] / speed[keep, None]
            V = vector_rows(layout, knots_rel, 1, times[keep])
            G = np.einsum("mi,min->mn", d, V)
            upper = np.full(int(keep.sum()), max(r.offset - margin, 0.5 * r.offset))
            out.append(ConstraintBlock(f"workspace refinement: {r.name}", G, np.full(upper.size, -np.inf), upper))
        elif r.kind == "sphere":
            times = np.unique(np.concatenate([_around(check, knots_rel, t0),
                                              _sample_times(knots_rel, 2 * ws.samples_per_segment)]))
            out.append(_sphere_block(f"workspace refinement: {r.name}",
                                     _position_rows(layout, knots_rel, times, None), r, traj(t0 + times), margin))
        else:
            times = _around(check, knots_rel, t0)
            taper = np.minimum(1.0, (tf_rel - times) / max(config.t_k, 1e-3)) if r.touches else np.ones(times.size)
            out.append(_plane_block(f"workspace refinement: {r.name}", _position_rows(layout, knots_rel, times, None),
                                    r.normal, r.offset + margin * taper))
    return tuple(out)
