"""QP rows of a line perch (:mod:`avp.line`): terminal conditions with the grasp point fixed or
free on the piece, thrust axis along the pitch normal, contact velocity and yaw; and sampled
guide rows (half-space clearance, minimum height, wedge corridor) that the certificates of
:mod:`avp.line_certify` then prove on the whole trajectory.

The free grasp point ``lambda`` is **eliminated**, not added to the decision vector: the
terminal CoM ``p(t_f) = A + lambda (B - A) + r n`` holds for some ``lambda`` iff the two
components of ``p(t_f) - A - r n`` across the line (along ``up`` and ``w``) vanish, and then
``lambda = d . (p(t_f) - A - r n) / |B - A|``, so ``lo <= lambda <= hi`` is one inequality row.
The layout (:mod:`avp.qp.layout`) and the equality elimination stay untouched.
"""

from __future__ import annotations

import math

import numpy as np

from .._typing import Array
from ..line import LineContact, LineTarget
from .assemble import ConstraintBlock
from .layout import YAW, DecisionLayout
from .rows import derivative_rows, vector_rows

E3 = np.array([0.0, 0.0, 1.0])


def contact_com(line: LineTarget, contact: LineContact, lam: float) -> Array:
    """CoM at contact for grasp fraction ``lam``: ``grasp + r n``."""
    return contact.grasp_point(lam) + line.gripper_offset * contact.n


def line_terminal_blocks(
    layout: DecisionLayout,
    knots_rel: Array,
    line: LineTarget,
    contact: LineContact,
    thrust_range: tuple[float, float],
    g: float,
    t_scale: float,
    rest_rates: bool = True,
    rotor_drag: float = 0.0,
) -> tuple[list[ConstraintBlock], list[ConstraintBlock]]:
    """Equality and inequality blocks at ``t_f``.

    Thrust (the analogue of (12) for a line): the thrust ``f = a(t_f) + g e3 + d v(t_f)`` has no
    component along ``d`` nor ``n x d``, so ``b3 = n``; its magnitude ``n . f`` lies in
    ``thrust_range``. ``d = rotor_drag`` (1/s, :class:`~avp.config.VehicleLimits`; Faessler et
    al.: ``b3 || a + g e3 + d v``). The contact velocity ``v(t_f) = -contact_speed n`` is itself
    an equality, so these rows are written on ``a(t_f)`` with ``d v(t_f)`` moved to the
    right-hand side (the same conditions; ``v`` along ``n`` leaves the tangential rows as
    without drag). With ``rest_rates`` the thrust's rate ``j + d a``, the yaw rate and the yaw
    jerk vanish at contact: the body rates and thrust rate are zero there, so the vehicle
    arrives in the perch attitude instead of rotating through it. Without drag that is a zero
    jerk, so with a zero contact velocity every odd derivative vanishes at ``t_f`` and the perch
    run backwards continues it up to snap (the fallback recovery of :mod:`avp.line_planner`,
    which with drag it does not: ``j(t_f) = -d a(t_f)``).
    """
    tf = float(knots_rel[-1])
    P = vector_rows(layout, knots_rel, 0, tf)[0]
    V = vector_rows(layout, knots_rel, 1, tf)[0]
    Acc = vector_rows(layout, knots_rel, 2, tf)[0]
    r, n, d = line.gripper_offset, contact.n, contact.d
    eq: list[ConstraintBlock] = []
    ineq: list[ConstraintBlock] = []
    if line.grasp is not None:
        com = contact_com(line, contact, line.grasp)
        eq.append(ConstraintBlock("line: gripper at the grasp point", P, com, com))
    else:
        base = contact.A + r * n
        across = np.stack([contact.up, contact.w])
        rhs = across @ base
        eq.append(ConstraintBlock("line: gripper on the line", across @ P, rhs, rhs))
        length = float(np.linalg.norm(contact.B - contact.A))
        row = (d @ P) / length
        off = float(d @ base) / length
        lo, hi = line.grasp_range
        ineq.append(ConstraintBlock("line: grasp point on the piece", row[None, :], np.array([lo + off]), np.array([hi + off])))
    s2 = t_scale**2
    tangents = np.stack([d, np.cross(n, d)])
    vel = -line.contact_speed * n
    drag_tf = rotor_drag * vel  # d v(t_f), fixed by the contact velocity row below
    rhs_t = -(g * tangents[:, 2] + tangents @ drag_tf) * s2
    eq.append(ConstraintBlock("line: thrust axis along n", (tangents @ Acc) * s2, rhs_t, rhs_t))
    lo_a, hi_a = thrust_range
    off = g * n[2] + float(n @ drag_tf)
    ineq.append(ConstraintBlock(
        "line: contact thrust range", (n @ Acc)[None, :] * s2,
        np.array([(lo_a - off) * s2]), np.array([(hi_a - off) * s2]),
    ))
    eq.append(ConstraintBlock("line: contact velocity", V * t_scale, vel * t_scale, vel * t_scale))
    if rest_rates:
        J = vector_rows(layout, knots_rel, 3, tf)[0] * t_scale**3
        if rotor_drag:  # the thrust's rate j + d a
            J = J + rotor_drag * t_scale * (Acc * s2)
            eq.append(ConstraintBlock("line: no rotation at contact (j + d a = 0)", J, np.zeros(3), np.zeros(3)))
        else:
            eq.append(ConstraintBlock("line: no rotation at contact (jerk 0)", J, np.zeros(3), np.zeros(3)))
        Y = np.stack([derivative_rows(layout, knots_rel, YAW, r, tf)[0] * t_scale**r for r in (1, 3)])
        eq.append(ConstraintBlock("line: yaw rate and yaw jerk 0 at contact", Y, np.zeros(2), np.zeros(2)))
    if contact.yaw is not None:
        Y = derivative_rows(layout, knots_rel, YAW, 0, tf)
        eq.append(ConstraintBlock("line: yaw at contact", Y, np.array([contact.yaw]), np.array([contact.yaw])))
    return eq, ineq


def halfspace_rows(
    layout: DecisionLayout, knots_rel: Array, times: Array, point: Array, normal: Array, margin: float, name: str
) -> ConstraintBlock:
    """``normal . (p(t_j) - point) >= margin`` at the sample ``times``."""
    P = vector_rows(layout, knots_rel, 0, times)  # (m, 3, n)
    G = np.einsum("i,min->mn", normal, P)
    lo = np.full(times.size, margin + float(normal @ point))
    return ConstraintBlock(name, G, lo, np.full(times.size, np.inf))


def wedge_normals(contact: LineContact, half_angle: float) -> tuple[Array, Array]:
    """Inward normals of the two half-planes through the line, tilted by ``+-half_angle`` about
    it from ``up``: the wedge is ``{x: m . (x - A) >= 0 for both}`` (angle to ``up`` <= half)."""
    c, s = math.cos(half_angle), math.sin(half_angle)
    # x = cos(th) up + sin(th) w has m . x = sin(half_angle -+ th): >= 0 iff |th| <= half_angle.
    return s * contact.up - c * contact.w, s * contact.up + c * contact.w


def snap_away_row(layout: DecisionLayout, knots_rel: Array, normal: Array, minimum: float, t_scale: float) -> ConstraintBlock:
    """``normal . snap(t0) >= minimum``: a start perched on the line leaves it (root of order 4)."""
    S = vector_rows(layout, knots_rel, 4, 0.0)[0]
    return ConstraintBlock("line: take-off snap away from the line", (normal @ S)[None, :] * t_scale**4,
                           np.array([minimum * t_scale**4]), np.array([np.inf]))


def thrust_direction_rows(
    layout: DecisionLayout, knots_rel: Array, times: Array, direction: Array, minimum: float, g: float, t_scale: float, name: str,
    rotor_drag: float = 0.0,
) -> ConstraintBlock:
    """``direction . (a(t_j) + g e3 + d v(t_j)) >= minimum`` at the sample ``times`` (linear in
    the coefficients; ``d = rotor_drag``, the thrust of :func:`line_terminal_blocks`)."""
    Acc = vector_rows(layout, knots_rel, 2, times)  # (m, 3, n)
    if rotor_drag:
        Acc = Acc + rotor_drag * vector_rows(layout, knots_rel, 1, times)
    G = np.einsum("i,min->mn", direction, Acc) * t_scale**2
    lo = np.full(times.size, (minimum - g * float(direction[2])) * t_scale**2)
    return ConstraintBlock(name, G, lo, np.full(times.size, np.inf))


def flip_blocks(
    layout: DecisionLayout, knots_rel: Array, times: Array, phases: tuple[float, float],
    before: Array, across: Array, after: Array, minimum: float, flip_thrust: float, g: float, t_scale: float,
    rotor_drag: float = 0.0,
) -> list[ConstraintBlock]:
    """A flip through the horizontal with the thrust bounded away from zero (pitch > 90 deg).

    The thrust ``f = a + g e3 + d v`` (``d = rotor_drag``) points along ``before``
    (``f . before >= minimum``) until ``phases[0]`` (s, from the plan start), along ``after``
    from ``phases[1]`` on, and in between
    ``f . across >= flip_thrust`` with ``across`` horizontal: ``f`` turns through the horizontal
    inside the middle window with ``|f| >= flip_thrust``, which keeps the tilt rate
    ``|j_perp| / |f|`` (22) finite. The certificate (thrust_min, tilt rate) is still the
    polynomial one of :func:`avp.bounds.certify_spline`.
    """
    t1, t2 = phases
    out = []
    for sel, direction, lo, name in (
        (times <= t1, before, minimum, "flip: thrust before"),
        ((times >= t1) & (times <= t2), across, flip_thrust, "flip: thrust across"),
        (times >= t2, after, minimum, "flip: thrust after"),
    ):
        if np.any(sel):
            out.append(thrust_direction_rows(layout, knots_rel, times[sel], direction, lo, g, t_scale, name, rotor_drag))
    return out
