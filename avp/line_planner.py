"""Plan a perch on a line (:class:`~avp.line.LineTarget`) and its recovery, with certificates.

:func:`plan_line` solves one minimum-snap QP (the cost (4) and boundary rows of :mod:`avp.qp`)
with the line's terminal conditions (:mod:`avp.qp.line`), certifies the vehicle limits with
:func:`avp.bounds.certify_spline`, the workspace limits of ``config.workspace`` (ground, extra
half-spaces, spheres, speed) with :func:`avp.safety.certify_workspace`, and the line clearance
and wedge corridor with :mod:`avp.line_certify`, searching the total duration (``config.bounds`` factors) until every
certificate holds. With ``config.limits.rotor_drag = d`` the contact thrust, its rest rates and
the flip rows are on the thrust ``a + g e3 + d v`` (:func:`avp.qp.line.line_terminal_blocks`);
the bound certificates prove the limits on that thrust, as for a pad. It then plans the **recovery**: a second spline that starts at the perch's
final state (continuous up to snap on all four flat outputs) and ends at rest at a safe hover
point, with the same certificates, as Paneque et al., "Perception-Aware Perching on Powerlines
with Multirotors", append a recovery to every perch. ``docs/lines.md`` has the derivations.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any

import numpy as np

from . import _validate as v
from ._blas import serial
from ._typing import Array
from .bounds import BoundReport, Certificate, certify_trajectory
from .config import ContactVelocity, PlannerConfig, Workspace
from .errors import ConfigError, InfeasibleError
from .line import LineContact, LineTarget
from .line_certify import (
    LineCertificate,
    PolyCheck,
    capsule_certificate,
    clearance_poly,
    halfplane_poly,
    position_polys,
    run_checks,
)
from .qp.assemble import ConstraintBlock, PerchingQp
from .qp.boundary import continuity_rows, initial_state_rows
from .qp.cost import cost_matrix
from .qp.layout import N_AXES, DecisionLayout, layout_for
from .qp.line import (
    contact_com,
    flip_blocks,
    halfspace_rows,
    line_terminal_blocks,
    snap_away_row,
    wedge_normals,
)
from .safety import certify_workspace, refinement_blocks, workspace_blocks
from .solve import solve_perching_qp
from .trajectory import Provenance, Trajectory
from .types import PerchTarget, State

__all__ = ["LineOptions", "LinePlanResult", "LineStatus", "perch_equivalent", "plan_line"]


ON_LINE_TOL = 1e-6
"""A start whose CoM is within this (m) of the clearance radius counts as perched on the line."""

NOT_USED = ("alpha", "alpha_nominal", "alpha_range", "q", "dt", "pre_impact", "band_min_width",
            "cone_half_angle", "cone_facets", "contact_velocity", "fov", "flip",
            "workspace.perch_clearance", "workspace.body_offset")
"""The :class:`~avp.config.PlannerConfig` settings of a pad perch that a line perch does not use
(``docs/lines.md``): its contact thrust and velocity are the line's own (:class:`LineOptions`,
:class:`~avp.line.LineTarget`), it has no pre-impact band (14) and no FoV rows (8)-(9), its flip
is :class:`LineOptions`'s, and the gripper offset replaces the body offset and the pad-plane
clearance. :func:`plan_line` logs the ones set away from their defaults
(:meth:`~avp.config.PlannerConfig.changed`)."""


RECOVERY_POINT_TOL = 1e-6
"""How far (m) a recovery may end from a given ``LineOptions.recovery_point`` and count as
reaching it (the perch flown backwards ends at the perch's start)."""


@v.typed_keywords("options")
@dataclass(frozen=True)
class LineOptions:
    """What a line perch adds to :class:`~avp.config.PlannerConfig`.

    Parameters
    ----------
    approach_deceleration:
        Minimum of ``n . a(t_f)`` (m/s^2): at zero contact speed the CoM must decelerate towards
        the line (otherwise it was closer to it just before contact). Sets the lower end of the
        contact thrust range ``n . f >= g n_z + this`` on the thrust ``f = a + g e3 + d v``
        (``d = limits.rotor_drag``; with a contact speed ``c`` that is ``n . a >= this + d c``).
    thrust_fraction:
        The contact thrust stays below this fraction of the maximum.
    guide_dt:
        Spacing (s) of the sampled guide rows (half-space clearance, height, wedge).
    wedge_angle:
        Full opening angle (rad) of the V-shaped corridor above the line over the last
        ``wedge_window`` seconds (Li et al.'s guide); ``None`` = no corridor.
    wedge_window:
        Length (s) of the final approach kept inside the wedge.
    takeoff_snap:
        Minimum snap (m/s^4) away from the line for a start perched on it.
    recovery:
        Plan the recovery.
    recovery_point:
        Hover point (m) the recovery ends at, above ``config.workspace.ground_z`` (``ConfigError``
        otherwise); ``None`` = ``recovery_distance`` along ``n`` from the contact CoM (raised to
        ``config.workspace.ground_z + recovery_height_margin``). With
        ``None`` a perch that ends upside down (or whose recovery QP fails) may recover by
        flying the perch backwards to its start; a point given here is not replaced by that
        (unless it is the start, within :data:`RECOVERY_POINT_TOL`): when no certified recovery
        reaches it, the status is ``NOT_CERTIFIED``.
    recovery_distance, recovery_height_margin:
        See ``recovery_point`` (m).
    ground_margin:
        The sampled height rows keep this much (m) above ``config.workspace.ground_z`` (the
        certificate checks ``ground_z`` itself, everywhere).
    flip_window, flip_thrust:
        For a contact thrust pointing below the horizontal (pitch > 90 deg): the thrust turns
        through the horizontal between ``flip_window[0]`` and ``flip_window[1]`` seconds before
        contact (after the start of the recovery, in reverse), with at least ``flip_thrust``
        (m/s^2) along ``w`` meanwhile (:func:`avp.qp.line.flip_blocks`). The upside-down phase
        is a coast faster than free fall, so it must be short in absolute time.
    flip_time:
        Time (s) added to the allocated perch duration for a 180 deg pitch, pro rata above
        90 deg (the allocation rule of :class:`~avp.config.TimeAllocation` knows no attitude).
    """

    approach_deceleration: float = 1.0
    thrust_fraction: float = 0.9
    guide_dt: float = 0.05
    wedge_angle: float | None = None
    wedge_window: float = 0.4
    takeoff_snap: float = 5.0
    recovery: bool = True
    recovery_point: Array | None = None
    recovery_distance: float = 1.0
    recovery_height_margin: float = 0.3
    ground_margin: float = 0.02
    flip_window: tuple[float, float] = (0.5, 0.15)
    flip_thrust: float = 4.0
    flip_time: float = 0.8

    def __post_init__(self) -> None:
        v.flags("options", self)
        v.positive_float("options.approach_deceleration", self.approach_deceleration)
        if not 0.0 < v.finite_float("options.thrust_fraction", self.thrust_fraction) <= 1.0:
            raise ConfigError("options.thrust_fraction", f"must be in (0, 1], got {self.thrust_fraction}")
        if v.positive_float("options.guide_dt", self.guide_dt) < 1e-3:
            raise ConfigError("options.guide_dt", f"must be at least 1 ms (one guide row per sample), got {self.guide_dt}")
        if self.wedge_angle is not None:
            a = v.finite_float("options.wedge_angle", self.wedge_angle)
            if not 0.0 < a < math.pi:
                raise ConfigError("options.wedge_angle", f"must be in (0, pi) rad, got {a}")
        v.positive_float("options.wedge_window", self.wedge_window)
        v.positive_float("options.takeoff_snap", self.takeoff_snap)
        if self.recovery_point is not None:
            object.__setattr__(self, "recovery_point", v.frozen_array("options.recovery_point", self.recovery_point, (3,)))
            v.within("options.recovery_point", self.recovery_point, "position")
        v.within("options.recovery_distance", v.positive_float("options.recovery_distance", self.recovery_distance),
                 "distance")
        v.positive_float("options.recovery_height_margin", self.recovery_height_margin)
        v.nonnegative_float("options.ground_margin", self.ground_margin)
        window = v.sequence("options.flip_window", self.flip_window, "two times (start, end), s")
        if len(window) != 2:
            raise ConfigError("options.flip_window", f"must be (start, end) seconds before contact, got {self.flip_window!r}")
        w0, w1 = (v.finite_float("options.flip_window", x) for x in window)
        if not w0 > w1 >= 0.0:
            raise ConfigError("options.flip_window", f"must be (start, end) seconds before contact with start > end >= 0, "
                              f"got {self.flip_window}")
        v.positive_float("options.flip_thrust", self.flip_thrust)
        v.nonnegative_float("options.flip_time", self.flip_time)


class LineStatus(Enum):
    SOLVED = "solved: perch (and recovery) planned and every certificate holds"
    NOT_CERTIFIED = "a trajectory exists but a certificate fails for every duration tried"
    INFEASIBLE = "infeasible: the QP has no solution for any duration tried"

    @property
    def has_trajectory(self) -> bool:
        """A certified plan was returned (the perch, and its recovery when
        ``LineOptions.recovery`` is on), as :attr:`avp.PlanStatus.has_trajectory` means for a
        pad. A ``NOT_CERTIFIED`` result still carries its last perch and recovery (``perch``,
        ``recovery``) for diagnostics; they are not to be flown."""
        return self is LineStatus.SOLVED


@dataclass(frozen=True, kw_only=True)
class LinePlanResult:
    """A line perch: the perch and recovery trajectories with their certificates.

    ``grasp`` is the grasp fraction ``lambda`` reached (the QP's choice when free);
    ``certificates`` lists every clearance / height / wedge verdict of both trajectories;
    ``bounds`` and ``recovery_bounds`` the actuator certificates. ``timings`` are seconds
    (``perch``, ``recovery``, ``total``).
    """

    status: LineStatus
    perch: Trajectory | None
    recovery: Trajectory | None
    contact: LineContact
    grasp: float
    certificates: tuple[LineCertificate, ...] = ()
    bounds: BoundReport | None = None
    recovery_bounds: BoundReport | None = None
    log: tuple[str, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status is LineStatus.SOLVED

    @property
    def trajectory(self) -> Trajectory | None:
        """The perch (the name :class:`~avp.planner.PlanResult` uses, for the replanner)."""
        return self.perch

    @property
    def relaxations(self) -> tuple[()]:
        """None: a line plan is never relaxed (the name :class:`~avp.planner.PlanResult` uses)."""
        return ()

    @property
    def violations(self) -> list[LineCertificate]:
        return [c for c in self.certificates if not c.ok]

    @property
    def clearance_slack(self) -> float:
        """Largest slack of the clearance certificates (m^2): ``dist^2 > r^2 - slack``."""
        return max((c.slack for c in self.certificates if c.name.startswith("clearance")), default=0.0)


# -- QP construction ---------------------------------------------------------------------------

def _guide_times(tf: float, dt: float, include_end: bool) -> Array:
    n = max(int(math.ceil(tf / dt)), 1)
    t = np.linspace(0.0, tf, n + 1)
    return t[1:] if include_end else t[1:-1]


def _base_qp(layout: DecisionLayout, T: Array, cfg: PlannerConfig, t0: float, A0: Array, b0: Array) -> tuple[Array, list[ConstraintBlock]]:
    t_scale = float(T.mean())
    P = cost_matrix(layout, T, cfg.position_cost_order, cfg.yaw_cost_order)
    Ac = continuity_rows(layout, T, cfg.continuity_order, t_scale)
    eq = [ConstraintBlock("initial state", A0, b0, b0),
          ConstraintBlock("continuity", Ac, np.zeros(Ac.shape[0]), np.zeros(Ac.shape[0]))]
    return P, eq


def _thrust_range(contact: LineContact, cfg: PlannerConfig, opts: LineOptions) -> tuple[float, float]:
    lim = cfg.limits
    lo = max(cfg.g * float(contact.n[2]) + opts.approach_deceleration, lim.accel_min + 0.05 * (lim.accel_max - lim.accel_min))
    if contact.n[2] < 0.0:  # after a flip: keep |f| up so the attitude is not spun at low thrust
        lo = max(lo, opts.flip_thrust)
    hi = opts.thrust_fraction * lim.accel_max
    if lo >= hi:
        raise ConfigError(
            "limits.thrust_max", f"the contact thrust needs >= {lo:.2f} m/s^2 (g n_z + approach deceleration) but "
            f"at most {hi:.2f} m/s^2 is allowed: raise the thrust limit or lower options.approach_deceleration")
    return lo, hi


def _perch_qp(state: State, line: LineTarget, contact: LineContact, cfg: PlannerConfig, opts: LineOptions,
              T: Array, on_line_normal: Array | None) -> PerchingQp:
    layout = layout_for(cfg.n_segments, cfg.degree)
    knots_rel = np.concatenate([[0.0], np.cumsum(T)])
    t_scale = float(T.mean())
    A0, b0 = initial_state_rows(layout, T, state, t_scale)
    P, eq = _base_qp(layout, T, cfg, state.time, A0, b0)
    teq, tineq = line_terminal_blocks(layout, knots_rel, line, contact, _thrust_range(contact, cfg, opts), cfg.g, t_scale,
                                      rotor_drag=cfg.limits.rotor_drag)
    eq += teq
    ineq = list(tineq)
    tf = float(knots_rel[-1])
    r = line.gripper_offset
    if float(contact.n @ (state.position - contact.A)) >= r - ON_LINE_TOL:
        times = _guide_times(tf, opts.guide_dt, include_end=False)
        ineq.append(halfspace_rows(layout, knots_rel, times, contact.A, contact.n, r, "line: guide half-space (clearance)"))
    ground = cfg.workspace.ground_z
    if ground is not None:
        times = _guide_times(tf, opts.guide_dt, include_end=True)
        ineq.append(halfspace_rows(layout, knots_rel, times, np.array([0.0, 0.0, ground]), np.array([0.0, 0.0, 1.0]), opts.ground_margin, "line: minimum height"))
    pseudo, ws = _workspace_view(contact_com(line, contact, line.grasp if line.grasp is not None else 0.5), contact.n, r, cfg.workspace)
    ineq += workspace_blocks(layout, knots_rel, state, pseudo, replace(cfg, workspace=replace(ws, ground_z=None)))
    if contact.n[2] < 0.0:
        tflip = _guide_times(tf, opts.guide_dt / 2.0, include_end=True)
        ineq += flip_blocks(layout, knots_rel, tflip, (tf - opts.flip_window[0], tf - opts.flip_window[1]), np.array([0.0, 0.0, 1.0]), contact.w, contact.n,
                            opts.flip_thrust, opts.flip_thrust, cfg.g, t_scale, cfg.limits.rotor_drag)
    if opts.wedge_angle is not None:
        tw = _guide_times(tf, opts.guide_dt / 2.0, include_end=True)
        tw = tw[tw >= tf - opts.wedge_window]
        for k, m in enumerate(wedge_normals(contact, opts.wedge_angle / 2.0)):
            ineq.append(halfspace_rows(layout, knots_rel, tw, contact.A, m, 0.0, f"line: wedge {k}"))
    if on_line_normal is not None:
        ineq.append(snap_away_row(layout, knots_rel, on_line_normal, opts.takeoff_snap, t_scale))
    return PerchingQp(layout=layout, durations=T, t0=state.time, P=P, equalities=tuple(eq), inequalities=tuple(ineq))


def _recovery_qp(perch: Trajectory, target_point: Array, contact: LineContact, line: LineTarget, cfg: PlannerConfig,
                 opts: LineOptions, T: Array) -> PerchingQp:
    """Recovery: all flat outputs continuous up to snap with the perch at ``t_f``; rest at
    ``target_point`` with the contact yaw at the end."""
    layout = layout_for(cfg.n_segments, cfg.degree)
    knots_rel = np.concatenate([[0.0], np.cumsum(T)])
    t_scale = float(T.mean())
    n = layout.n_coeffs
    B0, B1 = layout.endpoint_basis
    end = perch.derivatives(perch.tf)  # (5, 4)
    rows, rhs = [], []
    for axis in range(N_AXES):
        s0 = layout.start(axis, 0)
        sl = layout.start(axis, layout.n_segments - 1)
        for r in range(5):
            row = np.zeros(layout.n_variables)
            row[s0 : s0 + n] = B0[r] * (t_scale / T[0]) ** r
            rows.append(row)
            rhs.append(end[r, axis] * t_scale**r)
        for r in range(4 if axis < 3 else 3):
            row = np.zeros(layout.n_variables)
            row[sl : sl + n] = B1[r] * (t_scale / T[-1]) ** r
            rows.append(row)
            goal = (target_point[axis] if axis < 3 else end[0, 3]) if r == 0 else 0.0
            rhs.append(goal * t_scale**r)
    A0, b0 = np.array(rows), np.array(rhs)
    P, eq = _base_qp(layout, T, cfg, perch.tf, A0, b0)
    tf = float(knots_rel[-1])
    times = _guide_times(tf, opts.guide_dt, include_end=True)
    ineq = [halfspace_rows(layout, knots_rel, times, contact.A, contact.n, line.gripper_offset, "recovery: guide half-space (clearance)")]
    ground = cfg.workspace.ground_z
    if ground is not None:
        ineq.append(halfspace_rows(layout, knots_rel, times, np.array([0.0, 0.0, ground]), np.array([0.0, 0.0, 1.0]), opts.ground_margin, "recovery: minimum height"))
    pseudo, ws = _workspace_view(np.asarray(target_point, dtype=float), np.array([0.0, 0.0, 1.0]), 0.0, cfg.workspace)
    start = State(position=end[0, :3], velocity=end[1, :3], acceleration=end[2, :3], jerk=end[3, :3])
    ineq += workspace_blocks(layout, knots_rel, start, pseudo, replace(cfg, workspace=replace(ws, ground_z=None)))
    if contact.n[2] < 0.0:
        ineq += flip_blocks(layout, knots_rel, _guide_times(tf, opts.guide_dt / 2.0, include_end=True), opts.flip_window[::-1],
                            contact.n, contact.w, np.array([0.0, 0.0, 1.0]), opts.flip_thrust, opts.flip_thrust, cfg.g, t_scale,
                            cfg.limits.rotor_drag)
    return PerchingQp(layout=layout, durations=T, t0=perch.tf, P=P, equalities=tuple(eq), inequalities=tuple(ineq))


def _unflyable_end(perch: Trajectory) -> str | None:
    """Why the perch's end is no state a recovery can start from (its velocity, acceleration or
    jerk beyond ``avp._validate.LIMITS``, as a :class:`State` would refuse), or ``None``."""
    end = perch.derivatives(perch.tf)  # (5, 4)
    try:
        State(position=end[0, :3], velocity=end[1, :3], acceleration=end[2, :3], jerk=end[3, :3])
    except ConfigError as exc:
        return f"{exc.field.removeprefix('state.')} {exc.message}"
    return None


# -- certificates ------------------------------------------------------------------------------

def line_checks(traj: Trajectory, name: str, line: LineTarget, contact: LineContact, opts: LineOptions, *,
                contact_at_end: bool, start_root: tuple[int, int] | None) -> list[PolyCheck]:
    """Clearance from every piece (infinite lines) and wedge polynomials.

    ``start_root = (piece, order)`` marks a start on the clearance boundary of ``piece``.
    """
    checks: list[PolyCheck] = []
    S = traj.n_segments
    r = line.gripper_offset
    pos = [position_polys(traj, i) for i in range(S)]
    for k in range(line.n_pieces):
        A, B = line.piece(k)
        for i in range(S):
            F, scale = clearance_poly(pos[i], A, B, r)
            root_at, order = None, 0
            if contact_at_end and k == line.grasp_piece and i == S - 1:
                root_at, order = 1, (2 if line.contact_speed == 0.0 else 1)
            if start_root is not None and start_root[0] == k and i == 0:
                if root_at is not None:
                    raise ConfigError("config.n_segments", "a start on the line needs at least 2 segments")
                root_at, order = 0, start_root[1]
            checks.append(PolyCheck(f"clearance piece {k}", name, i, F, root_at=root_at, order=order, scale=scale))
    if opts.wedge_angle is not None and contact_at_end:
        ts = traj.duration - opts.wedge_window  # times relative to the plan's start
        for i in range(S):
            t0, t1 = float(traj.knots_rel[i]), float(traj.knots_rel[i + 1])
            if t1 <= ts:
                continue
            a = 0.0 if t0 >= ts else max(0.0, math.nextafter((ts - t0) / (t1 - t0), 0.0) * (1 - 1e-12))
            for k, m in enumerate(wedge_normals(contact, opts.wedge_angle / 2.0)):
                checks.append(PolyCheck(f"wedge {k}", name, i, halfplane_poly(pos[i], contact.A, m), a=a, b=1.0))
    return checks


def line_certificates(traj: Trajectory, name: str, line: LineTarget, contact: LineContact, opts: LineOptions, *,
                      contact_at_end: bool, start_root: tuple[int, int] | None) -> list[LineCertificate]:
    """Run :func:`line_checks`; a piece whose infinite line is not cleared (and that is not
    touched) is re-checked against the segment itself (:func:`~avp.line_certify.capsule_certificate`):
    on a catenary the extension of a far chord passes close to a CoM hanging below the sag."""
    checks = line_checks(traj, name, line, contact, opts, contact_at_end=contact_at_end, start_root=start_root)
    certs = run_checks(checks, {name: traj.knots})
    for j, (chk, cert) in enumerate(zip(checks, certs, strict=True)):
        if cert.ok or not chk.name.startswith("clearance piece") or chk.root_at is not None:
            continue
        k = int(chk.name.rsplit(" ", 1)[1])
        A, B = line.piece(k)
        certs[j] = capsule_certificate(position_polys(traj, chk.segment), A, B, line.gripper_offset,
                                       chk.name + " (segment)", name, chk.segment, traj.knots)
    return certs


def _workspace_view(com_end: Array, normal: Array, offset: float, workspace: Workspace) -> tuple[PerchTarget, Workspace]:
    """The line plan's end point as the "target" of :mod:`avp.safety`: a pad with normal
    ``normal`` whose contact CoM (``point + body_offset * s3``) is ``com_end``, and the
    workspace without the pad-plane clearance (a line is not a plane; its clearance is
    :mod:`avp.line_certify`'s)."""
    target = PerchTarget.from_normal(com_end - offset * normal, normal)
    return target, replace(workspace, perch_clearance=False, body_offset=offset)


def workspace_certificates(traj: Trajectory, name: str, com_end: Array, normal: Array, offset: float,
                           workspace: Workspace) -> list[LineCertificate]:
    """:func:`avp.safety.certify_workspace` verdicts as :class:`LineCertificate` rows
    (``slack`` = the certified contact residual in m)."""
    target, ws = _workspace_view(com_end, normal, offset, workspace)
    if not (ws.ground_z is not None or ws.half_spaces or ws.spheres or math.isfinite(ws.max_speed)):
        return []
    report = certify_workspace(traj, target, ws)
    out = []
    for chk in report.checks:
        for i, (verdict, t) in enumerate(zip(chk.verdicts, chk.times, strict=True)):
            if verdict is Certificate.WITHIN and not chk.certified:  # residual too large
                verdict = Certificate.VIOLATED
            out.append(LineCertificate(f"workspace: {chk.region.name}", name, i, verdict, float(t), chk.residual))
    return out


def workspace_refinement(traj: Trajectory, com_end: Array, normal: Array, offset: float, cfg: PlannerConfig,
                         round_index: int) -> tuple[ConstraintBlock, ...]:
    """Rows around the proven violations of ``traj``'s workspace certificates (those of
    :func:`workspace_certificates`), tightened for refinement round ``round_index``:
    :func:`avp.safety.refinement_blocks`, as a pad's plan refines (``workspace.refinement_rounds``,
    ``refinement_margin``). Empty when the workspace is certified."""
    target, ws = _workspace_view(com_end, normal, offset, cfg.workspace)
    report = certify_workspace(traj, target, ws)
    if report.certified:
        return ()
    layout = layout_for(cfg.n_segments, cfg.degree)
    return refinement_blocks(layout, traj.knots_rel, traj, report, round_index, replace(cfg, workspace=ws))


def _bounds(traj: Trajectory, cfg: PlannerConfig) -> BoundReport:
    return certify_trajectory(traj, cfg.limits, cfg.g)


def reversed_trajectory(traj: Trajectory, t0: float) -> Trajectory:
    """``traj`` run backwards from ``t0``: ``q(t0 + s) = p(t_f - s)``.

    Each segment ``p_i(tau) = sum c_k tau^k`` on ``[0, T_i]`` becomes ``sum c_k (T_i - tau)^k``.
    A perch that ends at rest with zero jerk, yaw rate and yaw jerk (every odd derivative 0) is
    continued by its reverse up to snap; the reverse flies back to the (safe) start point, and
    every bound and clearance is the perch's own (the certificates are recomputed anyway).
    """
    c = traj.coefficients
    T = traj.durations
    S, _axes, C = c.shape
    out = np.empty_like(c)
    k = np.arange(C)
    for i in range(S):
        Ti = float(T[S - 1 - i])
        src = c[S - 1 - i]
        for j in range(C):
            # q_j = (-1)^j sum_{k>=j} c_k C(k, j) T^{k-j}
            w = np.array([math.comb(int(kk), j) * Ti ** (kk - j) if kk >= j else 0.0 for kk in k])
            out[i, :, j] = (-1.0) ** j * (src @ w)
    return Trajectory.from_relative_knots(out, np.concatenate(([0.0], np.cumsum(T[::-1]))), t0=t0, g=traj.g)


# -- entry point -------------------------------------------------------------------------------

def _start_on_line(state: State, line: LineTarget) -> tuple[int, Array] | None:
    """``(piece, outward normal)`` if the start CoM sits on a piece's clearance boundary."""
    r = line.gripper_offset
    for k in range(line.n_pieces):
        A, B = line.piece(k)
        ab = B - A
        lam = float((state.position - A) @ ab / (ab @ ab))
        foot = A + min(1.0, max(0.0, lam)) * ab
        dist = float(np.linalg.norm(state.position - foot))
        if abs(dist - r) <= ON_LINE_TOL and 0.0 <= lam <= 1.0:
            return k, (state.position - foot) / dist
    return None


def _trajectory(qp: PerchingQp, cfg: PlannerConfig) -> Trajectory | str:
    """The solution of ``qp`` as a trajectory, or why there is none."""
    try:
        outcome = solve_perching_qp(qp, cfg)
    except InfeasibleError as exc:
        return str(exc)
    if not outcome.ok or outcome.c_hat is None:
        return f"QP {outcome.status.value}"
    return qp.trajectory(outcome.c_hat, cfg.g)


def _search(build: Any, certify: Any, factors: tuple[float, ...], T0: Array, cfg: PlannerConfig, log: list[str], label: str,
            refine: Any = None) -> tuple[Trajectory | None, bool, BoundReport | None, list[LineCertificate], float]:
    """Solve and certify for each duration factor; first fully certified wins. ``refine(traj,
    round)``: rows around the proven workspace violations of ``traj``; while a workspace
    certificate fails, up to ``workspace.refinement_rounds`` re-solves at the same durations
    add them (:func:`workspace_refinement`)."""
    best: tuple[Trajectory | None, bool, BoundReport | None, list[LineCertificate], float] = (None, False, None, [], math.nan)
    def verdicts(report: BoundReport, certs: list[LineCertificate], bad: list[LineCertificate]) -> str:
        return (f"bounds {'certified' if report.certified else 'NOT certified'}, "
                f"{len(certs) - len(bad)}/{len(certs)} line certificates" + (f" ({bad[0]})" if bad else ""))

    for factor in factors:
        T = T0 * factor
        try:
            qp = build(T)
        except InfeasibleError as exc:
            log.append(f"{label} x{factor:g}: {exc}")
            continue
        traj = _trajectory(qp, cfg)
        if isinstance(traj, str):
            log.append(f"{label} x{factor:g} (T = {T.sum():.3f} s): {traj}")
            continue
        report = _bounds(traj, cfg)
        if not report.certified and best[0] is not None:  # the line checks cannot rescue it
            log.append(f"{label} x{factor:g} (T = {T.sum():.3f} s): bounds NOT certified")
            continue
        certs = certify(traj)
        bad = [c for c in certs if not c.ok]
        log.append(f"{label} x{factor:g} (T = {T.sum():.3f} s): {verdicts(report, certs, bad)}")
        for round_index in range(1, cfg.workspace.refinement_rounds + 1 if refine is not None else 1):
            if not any(c.name.startswith("workspace") for c in bad):
                break
            extra = refine(traj, round_index)
            if not extra:
                break
            qp = qp.with_inequalities(*extra)
            refined = _trajectory(qp, cfg)
            if isinstance(refined, str):
                log.append(f"{label} x{factor:g} workspace refinement round {round_index}: {refined}")
                break
            traj, report = refined, _bounds(refined, cfg)
            certs = certify(traj)
            bad = [c for c in certs if not c.ok]
            log.append(f"{label} x{factor:g} workspace refinement round {round_index}: {verdicts(report, certs, bad)}")
        ok = report.certified and not bad
        if ok:
            return traj, True, report, certs, factor
        if best[0] is None:
            best = (traj, False, report, certs, factor)
    return best


@serial  # one BLAS thread: no helper threads spinning after the call (avp._blas)
def plan_line(
    state: State,
    line: LineTarget,
    config: PlannerConfig | None = None,
    options: LineOptions | None = None,
    *,
    duration: float | None = None,
    perch_search: bool = True,
) -> LinePlanResult:
    """Plan a perch on ``line`` from ``state`` and the recovery after it; never raises for an
    infeasible or uncertified plan (the status says so), only for bad input (ConfigError).

    ``duration`` overrides the total perch time of the allocation rule (the search still
    scales it by ``config.bounds`` factors). ``perch_search=False`` keeps the perch at exactly
    that time (the recovery still searches): a replan that keeps the committed contact time.
    """
    t_start = time.perf_counter()
    if not isinstance(state, State):
        raise ConfigError("state", f"expected avp.State, got {type(state).__name__}")
    if not isinstance(line, LineTarget):
        raise ConfigError("line", f"expected avp.LineTarget, got {type(line).__name__}")
    cfg = config if config is not None else PlannerConfig()
    if not isinstance(cfg, PlannerConfig):
        raise ConfigError("config", f"expected avp.PlannerConfig, got {type(cfg).__name__}")
    opts = options if options is not None else LineOptions()
    if not isinstance(opts, LineOptions):
        raise ConfigError("options", f"expected avp.LineOptions, got {type(opts).__name__}")
    perch_search = v.boolean("perch_search", perch_search)
    r = line.gripper_offset
    d0 = line.distance(state.position)
    if d0 < r - ON_LINE_TOL:
        raise ConfigError("state.position", f"is {d0:.4f} m from the line, inside its clearance radius (the gripper "
                          f"offset {r} m): start the perch farther from the line")
    ground = cfg.workspace.ground_z
    if ground is not None and state.position[2] <= ground:
        raise ConfigError("state.position", f"is at or below the minimum height config.workspace.ground_z = {ground} m")
    if ground is not None and opts.recovery_point is not None and opts.recovery_point[2] <= ground:
        raise ConfigError("options.recovery_point", f"is at or below the minimum height config.workspace.ground_z = "
                          f"{ground} m: give a hover point above it (or None for the default)")
    contact = line.contact(state.position, state.yaw)
    on_line = _start_on_line(state, line)
    if on_line is not None and cfg.n_segments < 2:
        raise ConfigError("config.n_segments", "a start perched on the line needs at least 2 segments")
    lam0 = line.grasp if line.grasp is not None else 0.5 * sum(line.grasp_range)
    goal = contact_com(line, contact, lam0)
    distance = float(np.linalg.norm(goal - state.position))
    if distance < cfg.min_distance and float(np.linalg.norm(state.velocity)) < 0.1:
        raise ConfigError("line", f"the contact point is {distance:.3f} m from a start at rest; nothing to plan")
    total = duration if duration is not None else cfg.time_allocation.total(distance, float(np.linalg.norm(state.velocity)))
    if duration is None:
        total += opts.flip_time * max(0.0, line.pitch - math.pi / 2) / (math.pi / 2)
    total = v.positive_float("duration", total)
    v.within("duration", total, "duration")
    T0 = np.full(cfg.n_segments, total / cfg.n_segments)
    factors = (1.0,) + (cfg.bounds.schedule() if cfg.bounds.certify else ())
    log: list[str] = []
    unused = cfg.changed(NOT_USED)
    if unused:
        log.append("config: a line perch does not use " + ", ".join(unused) + " (set away from the defaults; "
                   "docs/lines.md)")
    start_root = (on_line[0], 4) if on_line is not None else None
    on_normal = on_line[1] if on_line is not None else None

    def certify_perch(traj: Trajectory) -> list[LineCertificate]:
        certs = line_certificates(traj, "perch", line, contact, opts, contact_at_end=True, start_root=start_root)
        return certs + workspace_certificates(traj, "perch", traj(traj.tf), contact.n, r, cfg.workspace)

    def refine_perch(traj: Trajectory, round_index: int) -> tuple[ConstraintBlock, ...]:
        return workspace_refinement(traj, traj(traj.tf), contact.n, r, cfg, round_index)

    perch, ok, report, certs, _f = _search(
        lambda T: _perch_qp(state, line, contact, cfg, opts, T, on_normal), certify_perch,
        factors if perch_search else (1.0,), T0, cfg, log, "perch", refine_perch)
    t_perch = time.perf_counter() - t_start
    if perch is None:
        return LinePlanResult(status=LineStatus.INFEASIBLE, perch=None, recovery=None, contact=contact, grasp=math.nan, log=tuple(log), timings={"perch": t_perch, "recovery": 0.0, "total": t_perch})
    grasp = contact.grasp_fraction(perch(perch.tf) - r * contact.n)
    recovery = None
    rec_report = None
    rec_ok = True
    t_rec0 = time.perf_counter()
    unflyable = _unflyable_end(perch) if opts.recovery else None
    if unflyable is not None:  # an uncertified perch (durations far too short) ends in no flight's state
        rec_ok = False
        log.append(f"recovery: not planned: the perch's end {unflyable}; no recovery starts there "
                   "(give a longer duration)")
    elif opts.recovery:
        end = perch(perch.tf)
        if opts.recovery_point is not None:  # the user's: as given (above the ground, checked above)
            point = np.array(opts.recovery_point, dtype=float)
        else:
            point = end + opts.recovery_distance * contact.n
            if ground is not None:
                point[2] = max(point[2], ground + opts.recovery_height_margin)
        rT0 = np.full(cfg.n_segments, cfg.time_allocation.total(float(np.linalg.norm(point - end)), 0.0) / cfg.n_segments)

        def certify_recovery(traj: Trajectory) -> list[LineCertificate]:
            certs = line_certificates(traj, "recovery", line, contact, opts, contact_at_end=False,
                                      start_root=(line.grasp_piece, 2 if line.contact_speed == 0.0 else 1))
            return certs + workspace_certificates(
                traj, "recovery", traj(traj.tf), np.array([0.0, 0.0, 1.0]), 0.0, cfg.workspace)

        def refine_recovery(traj: Trajectory, round_index: int) -> tuple[ConstraintBlock, ...]:
            return workspace_refinement(traj, traj(traj.tf), np.array([0.0, 0.0, 1.0]), 0.0, cfg, round_index)

        build = lambda T: _recovery_qp(perch, point, contact, line, cfg, opts, T)
        rcerts: list[LineCertificate] = []
        recovery, rec_ok, rec_report = None, False, None
        explicit = opts.recovery_point is not None  # the perch backwards ends at the start, maybe not there
        if contact.n[2] >= 0.0 or explicit or line.contact_speed != 0.0 or cfg.limits.rotor_drag:  # else the reverse first
            recovery, rec_ok, rec_report, rcerts, _rf = _search(build, certify_recovery, (1.0,), rT0, cfg, log, "recovery",
                                                                      refine_recovery)
        at_rest = not (np.any(state.velocity) or np.any(state.acceleration) or np.any(state.jerk))
        if not rec_ok and line.contact_speed == 0.0 and at_rest and cfg.limits.rotor_drag:
            # with drag the perch ends with j = -d a (no rotation), which its reverse does not continue
            log.append("recovery = perch backwards: not with rotor drag (the perch ends with jerk -d a, "
                       "which the reverse does not continue)")
        elif not rec_ok and line.contact_speed == 0.0 and at_rest:
            # Upside down (or when the QP recovery fails): fly the perch backwards to its start
            # (a hover only when the perch started at rest).
            back = reversed_trajectory(perch, perch.tf)
            back_report = _bounds(back, cfg)
            back_certs = certify_recovery(back)
            back_ok = back_report.certified and all(c.ok for c in back_certs)
            elsewhere = explicit and float(np.linalg.norm(back(back.tf) - point)) > RECOVERY_POINT_TOL
            log.append(f"recovery = perch backwards (T = {back.duration:.3f} s): "
                       + ("certified" if back_ok else "NOT certified")
                       + ("; not counted: it ends at the start, not at options.recovery_point" if elsewhere else ""))
            back_ok = back_ok and not elsewhere
            if back_ok or recovery is None:
                recovery, rec_ok, rec_report, rcerts = back, back_ok, back_report, back_certs
        if not rec_ok and len(factors) > 1:
            again = _search(build, certify_recovery, factors[1:], rT0, cfg, log, "recovery", refine_recovery)
            if again[1] or recovery is None:
                recovery, rec_ok, rec_report, rcerts, _rf = again
        certs = certs + rcerts
        if recovery is None:
            rec_ok = False
            log.append("recovery: no QP solution for any duration")
    t_rec = time.perf_counter() - t_rec0
    status = LineStatus.SOLVED if ok and rec_ok else LineStatus.NOT_CERTIFIED
    for traj, bounds, label in ((perch, report, "perch"), (recovery, rec_report, "recovery")):
        if traj is not None:  # the status and the certificates travel with each spline (exports included)
            mine = [c for c in certs if c.trajectory == label]
            traj.provenance = Provenance(status=status.value, bounds_certified=bool(bounds is not None and bounds.certified),
                                         workspace_certified=bool(mine) and all(c.ok for c in mine))
    return LinePlanResult(status=status, perch=perch, recovery=recovery, contact=contact, grasp=grasp, certificates=tuple(certs), bounds=report, recovery_bounds=rec_report, log=tuple(log), timings={"perch": t_perch, "recovery": t_rec, "total": time.perf_counter() - t_start})


def perch_equivalent(
    state: State, line: LineTarget, config: PlannerConfig | None = None, options: LineOptions | None = None
) -> tuple[PerchTarget, PlannerConfig]:
    """A plane perch that the plane planner, :class:`~avp.Replanner` and the simulator accept,
    whose own certificates imply the line's clearance (an adapter, conservative).

    The pad is the plane through the line with normal ``n`` (it contains the line, ``n ⟂ d``),
    centred at the grasp point (the middle of ``grasp_range`` when free), with
    ``R_WS = [d x n, d, n]`` so the terminal yaw (13) puts ``b2`` along the line (``ACROSS``).
    The workspace gets ``perch_clearance`` with ``body_offset = gripper_offset``: the certified
    ``n . (p - point) > r`` before contact keeps the CoM farther than ``r`` from every point of
    the plane, hence from the line. The contact velocity is ``-contact_speed n`` (with a zero
    contact speed the normal component is left free: the plane planner rejects a contact that
    does not move into the pad, :mod:`avp.request`), the contact thrust
    ``g n_z + approach_deceleration``. What it does not carry over: a zero-speed contact, a free
    grasp point, ``ALONG``/``FREE`` yaw, the wedge and the flip corridor; use :func:`plan_line`.
    """
    cfg = config if config is not None else PlannerConfig()
    opts = options if options is not None else LineOptions()
    contact = line.contact(state.position, state.yaw)
    lam = line.grasp if line.grasp is not None else 0.5 * sum(line.grasp_range)
    n, d = contact.n, contact.d
    target = PerchTarget(point=contact.grasp_point(lam), R_WS=np.column_stack([np.cross(d, n), d, n]))
    lim = cfg.limits
    margin = 0.05 * (lim.accel_max - lim.accel_min)
    alpha = min(max(cfg.g * float(n[2]) + opts.approach_deceleration, lim.accel_min + margin), lim.accel_max - margin)
    out = replace(
        cfg, alpha=alpha, alpha_range=None,
        contact_velocity=ContactVelocity(normal=-line.contact_speed if line.contact_speed > 0.0 else None, slope=0.0,
                                         lateral=0.0, scale_slope_with_incline=False),
        workspace=replace(cfg.workspace, perch_clearance=True, body_offset=line.gripper_offset),
    )
    return target, out
