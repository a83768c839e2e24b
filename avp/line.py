"""Line and powerline perch targets: :class:`LineTarget` and its resolved contact geometry.

A line target is a polyline (a straight segment, or a catenary approximated by several segments)
that the gripper grasps. The gripper sits ``gripper_offset`` below the centre of mass along
``-b3``, so at contact the CoM is ``grasp + gripper_offset * n`` with ``n`` the commanded
thrust axis. ``n`` is set by the final pitch about the line: 0 = on top (``n`` is the upward
normal of the line), 180 deg = hanging below, upside down (``n`` points down). This follows the
perching manoeuvres of Paneque et al., "Perception-Aware Perching on Powerlines with
Multirotors" (final pitch 20, 80, 180 deg), the landing on a ground wire of Li et al.,
"Model-Based Trajectory Planning of a Hybrid Robot for Powerline Inspection" (heading along the
wire), and Mohta, Kumar and Daniilidis, "Vision-based Control of a Quadrotor for Perching on
Lines" (lines inclined 0-26.6 deg). The planner is :mod:`avp.line_planner`; ``docs/lines.md``
has the derivations.

Frames (all in W): for the grasped piece with unit direction ``d``, ``u`` is the unit normal of
the line in the vertical plane that contains it (``u . e3 > 0``), ``w = d x u`` is horizontal,
and ``n(pitch) = cos(pitch) u + sin(pitch) w_side`` where ``w_side = +-w`` points to the side the
vehicle arrives from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any

import numpy as np
import scipy.optimize

from . import _validate as v
from ._typing import Array
from ._values import fields_equal, fields_hash
from .errors import ConfigError
from .frames import yaw_from_b2

__all__ = ["LineContact", "LineTarget", "LineYaw"]

E3 = np.array([0.0, 0.0, 1.0])

MAX_INCLINE = math.radians(80.0)
"""Steepest accepted line (rad from horizontal): the pitch about a near-vertical line is undefined."""


class LineYaw(Enum):
    """Yaw at contact."""

    ACROSS = "pitch axis b2 along the line: the vehicle pitches about it (Paneque et al.)"
    ALONG = "heading b1 along the line: the guide straddles it (Li et al., Mohta et al.)"
    FREE = "yaw at contact left to the optimiser"


@v.typed_keywords("line")
@dataclass(frozen=True, eq=False)
class LineTarget:
    """A line to perch on.

    Parameters
    ----------
    vertices:
        ``(K + 1, 3)`` points of the polyline (W, m); two points for a straight segment. See
        :meth:`catenary` for a sagging cable.
    radius:
        Cable radius (m); the gripper offset must exceed it.
    gripper_offset:
        Distance from the CoM to the gripper along ``-b3`` (m). Also the clearance: the CoM
        stays farther than this from the line until contact.
    pitch:
        Final pitch about the line (rad), in ``[0, pi]``: 0 on top, ``pi`` hanging below.
    grasp:
        Fraction ``lambda`` in ``[0, 1]`` along piece ``grasp_piece`` where the gripper closes;
        ``None`` leaves it free within ``grasp_range`` (a decision of the QP).
    grasp_piece:
        Index of the polyline piece that is grasped.
    grasp_range:
        ``(lo, hi)``, ``0 <= lo < hi <= 1``: the free grasp point stays in this part of the piece.
    contact_speed:
        Speed (m/s) along ``-n`` at contact (0: the gripper arrives at rest on the line).
    yaw:
        :class:`LineYaw`.
    side:
        Horizontal direction from the line towards the side the vehicle arrives from; ``None``
        takes the side of the start position (needed only for ``0 < pitch < pi``).
    """

    vertices: Array
    radius: float = 0.01
    gripper_offset: float = 0.12
    pitch: float = 0.0
    grasp: float | None = 0.5
    grasp_piece: int = 0
    grasp_range: tuple[float, float] = (0.05, 0.95)
    contact_speed: float = 0.0
    yaw: LineYaw = LineYaw.ACROSS
    side: Array | None = None

    __eq__ = fields_equal  # values, not identity (module _values)
    __hash__ = fields_hash

    def __post_init__(self) -> None:
        try:
            raw = np.array(self.vertices, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ConfigError("line.vertices", f"expected (K + 1, 3) numbers, got {self.vertices!r}") from exc
        if raw.ndim != 2 or raw.shape[1] != 3 or raw.shape[0] < 2:
            raise ConfigError("line.vertices", f"expected shape (K + 1, 3) with K >= 1, got {raw.shape}")
        verts = v.frozen_array("line.vertices", raw, raw.shape)
        v.within("line.vertices", verts, "position")
        lengths = np.linalg.norm(np.diff(verts, axis=0), axis=1)
        if np.any(lengths < 1e-6):
            k = int(np.argmin(lengths))
            raise ConfigError("line.vertices", f"piece {k} has zero length ({lengths[k]:.2e} m); pass distinct points")
        slopes = np.arcsin(np.clip(np.abs(np.diff(verts, axis=0)[:, 2]) / lengths, 0.0, 1.0))
        if np.any(slopes > MAX_INCLINE):
            raise ConfigError(
                "line.vertices", f"a piece is inclined {math.degrees(float(slopes.max())):.1f} deg; at most "
                f"{math.degrees(MAX_INCLINE):.0f} deg is supported (pitch about a vertical line is undefined)")
        object.__setattr__(self, "vertices", verts)
        radius = v.finite_float("line.radius", self.radius)
        if radius < 0.0:
            raise ConfigError("line.radius", f"must be >= 0 m, got {radius}")
        object.__setattr__(self, "radius", radius)
        offset = v.positive_float("line.gripper_offset", self.gripper_offset)
        v.within("line.gripper_offset", offset, "distance")
        if offset <= radius:
            raise ConfigError("line.gripper_offset", f"({offset} m) must exceed the cable radius ({radius} m)")
        object.__setattr__(self, "gripper_offset", offset)
        pitch = v.finite_float("line.pitch", self.pitch)
        if not 0.0 <= pitch <= math.pi:
            raise ConfigError("line.pitch", f"must be in [0, pi] rad (0 on top, pi hanging below), got {pitch}")
        object.__setattr__(self, "pitch", pitch)
        v.integer("line.grasp_piece", self.grasp_piece, 0, verts.shape[0] - 2, "(a piece index)")
        pair = v.sequence("line.grasp_range", self.grasp_range, "two fractions (lo, hi)")
        if len(pair) != 2:
            raise ConfigError("line.grasp_range", f"must be (lo, hi) with 0 <= lo < hi <= 1, got {self.grasp_range!r}")
        lo, hi = (v.finite_float("line.grasp_range", x) for x in pair)
        if not 0.0 <= lo < hi <= 1.0:
            raise ConfigError("line.grasp_range", f"must be (lo, hi) with 0 <= lo < hi <= 1, got {self.grasp_range}")
        object.__setattr__(self, "grasp_range", (lo, hi))
        if self.grasp is not None:
            lam = v.finite_float("line.grasp", self.grasp)
            if not 0.0 <= lam <= 1.0:
                raise ConfigError("line.grasp", f"must be in [0, 1] along the piece (or None = free), got {lam}")
            object.__setattr__(self, "grasp", lam)
        speed = v.finite_float("line.contact_speed", self.contact_speed)
        v.within("line.contact_speed", speed, "velocity")
        if speed < 0.0:
            raise ConfigError("line.contact_speed", f"must be >= 0 m/s (along -n, into the line), got {speed}")
        object.__setattr__(self, "contact_speed", speed)
        if not isinstance(self.yaw, LineYaw):
            raise ConfigError("line.yaw", f"must be a LineYaw, got {self.yaw!r}")
        if self.side is not None:
            s = np.array(v.frozen_array("line.side", self.side, (3,)))
            s[2] = 0.0
            s = v.unit_vector("line.side", s, "must have a horizontal component")
            s.setflags(write=False)
            object.__setattr__(self, "side", s)

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def segment(cls, start: Any, end: Any, **kwargs: Any) -> LineTarget:
        """A straight segment from ``start`` to ``end``."""
        _check_settings(kwargs)
        p0 = v.frozen_array("line.start", start, (3,))
        p1 = v.frozen_array("line.end", end, (3,))
        return cls(vertices=np.array([p0, p1]), **kwargs)

    @classmethod
    def catenary(cls, start: Any, end: Any, sag: float, pieces: int = 8, **kwargs: Any) -> LineTarget:
        """A cable hanging between ``start`` and ``end`` with ``sag`` (m, below the chord's
        midpoint), approximated by ``pieces`` chords of the catenary ``z = a cosh(x/a) + c``."""
        _check_settings(kwargs, ("start", "end", "sag", "pieces"))
        p0 = v.frozen_array("line.start", start, (3,))
        p1 = v.frozen_array("line.end", end, (3,))
        sag_ = v.positive_float("line.sag", sag)
        if isinstance(pieces, bool) or not isinstance(pieces, int) or pieces < 1:
            raise ConfigError("line.pieces", f"must be an integer >= 1, got {pieces!r}")
        horiz = p1[:2] - p0[:2]
        span = float(np.linalg.norm(horiz))
        if span < 1e-6:
            raise ConfigError("line.end", "a catenary needs a horizontal span between its ends")
        dz = float(p1[2] - p0[2])

        def shape(a: float) -> tuple[float, float]:
            # Catenary through (0, 0) and (span, dz): z = a (cosh((x - x0)/a) - cosh(x0/a)).
            x0 = span / 2.0 - a * math.asinh(dz / (2.0 * a * math.sinh(span / (2.0 * a))))
            return x0, a

        def z_of(x: float, a: float) -> float:
            x0, _ = shape(a)
            return a * (math.cosh((x - x0) / a) - math.cosh(x0 / a))

        def sag_of(a: float) -> float:
            return (dz / 2.0) - z_of(span / 2.0, a) - sag_

        try:
            a = float(scipy.optimize.brentq(sag_of, span / 1e3, span * 1e4))
        except (ValueError, OverflowError) as exc:
            raise ConfigError("line.sag", f"no catenary with sag {sag_} m over a {span:.3f} m span") from exc
        xs = np.linspace(0.0, span, pieces + 1)
        pts = np.array([[*(p0[:2] + horiz * (x / span)), p0[2] + z_of(float(x), a)] for x in xs])
        pts[-1] = p1
        return cls(vertices=pts, **kwargs)

    # -- geometry -------------------------------------------------------------------------
    @property
    def n_pieces(self) -> int:
        return int(self.vertices.shape[0] - 1)

    def piece(self, k: int) -> tuple[Array, Array]:
        """End points ``(A, B)`` of piece ``k``."""
        return self.vertices[k], self.vertices[k + 1]

    def distance(self, point: Any) -> float:
        """Distance (m) from ``point`` to the polyline (closest piece, end points included)."""
        return self.closest(point)[1]

    def closest(self, point: Any) -> tuple[int, float]:
        """The piece closest to ``point`` (the first of equals) and its distance (m), end points
        included."""
        p = v.frozen_array("point", point, (3,))
        best, index = math.inf, 0
        for k in range(self.n_pieces):
            A, B = self.piece(k)
            ab = B - A
            lam = min(1.0, max(0.0, float((p - A) @ ab / (ab @ ab))))
            dist = float(np.linalg.norm(p - A - lam * ab))
            if dist < best:
                best, index = dist, k
        return index, best

    def contact(self, start: Any, yaw_near: float = 0.0) -> LineContact:
        """The resolved contact geometry for a vehicle starting at ``start``."""
        A, B = self.piece(self.grasp_piece)
        d = (B - A) / np.linalg.norm(B - A)
        up = E3 - (E3 @ d) * d
        up = up / np.linalg.norm(up)
        w = np.cross(d, up)
        side = self.side
        if side is None:
            rel = np.asarray(start, dtype=float) - A
            side = w if float(rel @ w) >= 0.0 else -w
        w_side = w if float(side @ w) >= 0.0 else -w
        n = math.cos(self.pitch) * up + math.sin(self.pitch) * w_side
        n = n / np.linalg.norm(n)
        psi = _contact_yaw(self.yaw, d, n, yaw_near)
        return LineContact(A=A, B=B, d=d, up=up, w=w_side, n=n, yaw=psi)


def _check_settings(kwargs: dict[str, Any], own: tuple[str, ...] = ("start", "end")) -> None:
    """A constructor's keywords are :class:`LineTarget` fields (not ``vertices``, which it builds)
    or its ``own`` arguments, checked before the constructor builds the vertices."""
    names = tuple(f.name for f in fields(LineTarget) if f.name != "vertices")
    v.keywords("line", LineTarget, names, kwargs, own)


@dataclass(frozen=True)
class LineContact:
    """Resolved geometry of a :class:`LineTarget` for one start: the grasped piece ``A -> B``,
    its unit direction ``d``, up normal ``up``, the side normal ``w`` (towards the vehicle),
    the commanded thrust axis ``n`` and the yaw at contact (``None`` = free)."""

    A: Array
    B: Array
    d: Array
    up: Array
    w: Array
    n: Array
    yaw: float | None

    def grasp_point(self, lam: float) -> Array:
        return self.A + lam * (self.B - self.A)

    def grasp_fraction(self, point: Any) -> float:
        """``lambda`` of the projection of ``point`` on the piece (unclipped)."""
        ab = self.B - self.A
        return float((np.asarray(point, dtype=float) - self.A) @ ab / (ab @ ab))


def _contact_yaw(mode: LineYaw, d: Array, n: Array, near: float) -> float | None:
    """Yaw whose attitude (13) has ``b2`` (ACROSS) or ``b1`` (ALONG) as close to ``+-d`` as the
    construction allows, unwrapped to within pi of ``near`` (and the sign of ``d`` that needs
    the least turn)."""
    if mode is LineYaw.FREE:
        return None
    if mode is LineYaw.ALONG:
        # b1 along d: b2_des is the horizontal direction perpendicular to d.
        h = np.cross(E3, d)
        b2 = h
    else:
        # b2 along d: b2_des is the horizontal vector of span(d, n).
        b2 = n[2] * d - d[2] * n
        nb = float(np.linalg.norm(b2))
        if nb < 1e-9 or np.linalg.norm(np.cross(b2 / nb, n)) < 0.1:
            # (13) is singular when b2_des is parallel to b3 (n horizontal, line inclined):
            # take the line's horizontal projection, orthogonal to a horizontal n.
            b2 = np.array([d[0], d[1], 0.0])
    b2 = np.asarray(b2, dtype=float)
    best: float | None = None
    for sign in (1.0, -1.0):
        psi = yaw_from_b2(sign * b2)
        psi = psi + 2.0 * math.pi * round((near - psi) / (2.0 * math.pi))
        if best is None or abs(psi - near) < abs(best - near):
            best = psi
    return best
