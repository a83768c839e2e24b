"""The front camera and the settings of the perception-aware planning (FoV rows (7)-(9), (16)).

Camera frame C (same convention as :mod:`avp.sim.camera`): the optical axis is ``c3``; image
``x`` is ``c1`` and image ``y`` is ``c2`` (OpenCV style: ``c1`` to the right, ``c2`` down in the
image). The mounting rotation ``R_BC`` has columns ``c1, c2, c3`` in body coordinates. The default
front camera looks along ``b1`` with ``c1 = -b2`` and ``c2 = -b3``:
``R_BC = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]``. The camera sits at the centre of mass (no offset).

The target point ``s`` is visible from ``x`` with attitude ``R_WB`` when it lies inside the
one-sided cone (7) of half-angle ``half_fov`` about ``e_c = R_WB R_BC e3``::

    cos(half_fov) |n_d| <= n_d . e_c,    n_d = s - x,

and ``0 < |n_d| <= range``. When ``horizontal_fov`` / ``vertical_fov`` are given, the target
must in addition lie inside the rectangular image pyramid (used by :func:`avp.metrics.visibility`;
the planner's rows (8) use the cone only, which is the paper's model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _validate as v
from ._typing import Array
from .errors import ConfigError

__all__ = ["FRONT_CAMERA_R_BC", "Camera", "FovConfig", "FovPointPolicy"]


FRONT_CAMERA_R_BC = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Default mounting: optical axis ``c3 = b1`` (forward), ``c1 = -b2``, ``c2 = -b3``."""
FRONT_CAMERA_R_BC.setflags(write=False)


def _default_R_BC() -> Array:
    return FRONT_CAMERA_R_BC.copy()


@dataclass(frozen=True, eq=False)
class Camera:
    """A rigidly mounted pinhole camera with a conical field of view.

    Parameters
    ----------
    R_BC:
        Mounting rotation (columns ``c1, c2, c3`` in B; ``c3`` is the optical axis). Default:
        the front camera, optical axis along ``b1`` (module docstring).
    half_fov:
        Half-angle of the FoV cone (7) (rad); default 35 deg, the paper's 70 deg front camera.
    horizontal_fov, vertical_fov:
        Optional full angles (rad) of the rectangular image; ``None``: cone only.
    range:
        Largest distance at which the target counts as visible (m); ``inf``: no limit.
    """

    R_BC: Any = field(default_factory=_default_R_BC)
    half_fov: float = math.radians(35.0)
    horizontal_fov: float | None = None
    vertical_fov: float | None = None
    range: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, "R_BC", v.rotation("camera.R_BC", self.R_BC))
        hf = v.finite_float("camera.half_fov", self.half_fov)
        if not 0.0 < hf < math.pi / 2:
            raise ConfigError("camera.half_fov", f"must be in (0, pi/2) rad, got {hf}")
        object.__setattr__(self, "half_fov", hf)
        for name in ("horizontal_fov", "vertical_fov"):
            val = getattr(self, name)
            if val is not None:
                val = v.finite_float(f"camera.{name}", val)
                if not 0.0 < val < math.pi:
                    raise ConfigError(f"camera.{name}", f"must be in (0, pi) rad (full angle), got {val}")
                object.__setattr__(self, name, val)
        object.__setattr__(self, "range", v.positive_float("camera.range", self.range, allow_inf=True))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (
            bool(np.array_equal(self.R_BC, other.R_BC))
            and (self.half_fov, self.horizontal_fov, self.vertical_fov, self.range)
            == (other.half_fov, other.horizontal_fov, other.vertical_fov, other.range)
        )

    def __hash__(self) -> int:
        return hash((self.R_BC.tobytes(), self.half_fov, self.horizontal_fov, self.vertical_fov, self.range))

    @property
    def axis_B(self) -> Array:
        """Optical axis ``c3`` in body coordinates."""
        return self.R_BC[:, 2]

    def axis(self, R_WB: npt.ArrayLike) -> Array:
        """Optical axis ``e_c = R_WB R_BC e3`` in W; ``R_WB`` of shape ``(..., 3, 3)``."""
        return np.asarray(R_WB, dtype=float) @ self.axis_B

    def R_WC(self, R_WB: npt.ArrayLike) -> Array:
        """Camera attitude in W, ``R_WB R_BC`` (shape ``(..., 3, 3)``)."""
        return np.asarray(R_WB, dtype=float) @ self.R_BC

    def sees(self, position: npt.ArrayLike, R_WB: npt.ArrayLike, point: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether ``point`` (W) is inside the FoV (cone (7), image rectangle, range) from
        ``position`` with attitude ``R_WB``; vectorised over leading axes. A point at the camera
        centre (``|n_d| = 0``) is not visible."""
        x = np.asarray(position, dtype=float)
        n_d = np.asarray(point, dtype=float) - x
        dist = np.linalg.norm(n_d, axis=-1)
        n_C = np.einsum("...ji,...j->...i", self.R_WC(R_WB), n_d)  # R_WC^T n_d
        ok = (dist > 1e-12) & (dist <= self.range) & (math.cos(self.half_fov) * dist <= n_C[..., 2])
        if self.horizontal_fov is not None:
            ok &= np.abs(n_C[..., 0]) <= math.tan(self.horizontal_fov / 2) * n_C[..., 2]
        if self.vertical_fov is not None:
            ok &= np.abs(n_C[..., 1]) <= math.tan(self.vertical_fov / 2) * n_C[..., 2]
        return ok


class FovPointPolicy(Enum):
    """What to do with a FoV point whose linearised row (8) cannot hold anywhere inside its trust
    region (9) (the target is too far outside the cone at the linearisation point).

    Such a row makes the whole QP infeasible, so the fallback (16) would drop *every* FoV row.
    """

    SKIP = "skip: leave the point without a FoV row"
    PROGRESS = "progress: require a fraction of the decrease of h reachable inside the trust region"
    KEEP = "keep: place the row as is (the QP is infeasible and the fallback (16) fires)"


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
        (0: the cone itself). A small positive value absorbs linearisation error.
    sqp_iterations:
        Cap on SQP steps for a first plan (no previous plan): solve without FoV, then linearise
        around the last solution and re-solve while the visibility improves, at most this often.
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
    fallback_max_iter: int | None = 4000
    camera: Camera = field(default_factory=Camera)

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ConfigError("fov.enabled", f"must be a bool, got {self.enabled!r}")
        for name, lo in (("n_points", 1), ("sqp_iterations", 1)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
                raise ConfigError(f"fov.{name}", f"must be an integer >= {lo}, got {val!r}")
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
