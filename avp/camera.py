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
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _validate as v
from ._typing import Array
from .errors import ConfigError

__all__ = ["FRONT_CAMERA_R_BC", "Camera"]


FRONT_CAMERA_R_BC = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Default mounting: optical axis ``c3 = b1`` (forward), ``c1 = -b2``, ``c2 = -b3``."""
FRONT_CAMERA_R_BC.setflags(write=False)


def _default_R_BC() -> Array:
    return FRONT_CAMERA_R_BC.copy()


@v.typed_keywords("camera")
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

    @classmethod
    def front(cls, uptilt: float = 0.0, **kwargs: Any) -> Camera:
        """The front camera (:data:`FRONT_CAMERA_R_BC`) with its optical axis tilted up by
        ``uptilt`` rad: turned about ``b2`` from ``b1`` towards ``b3``, so that it looks above
        the horizon when the vehicle hovers (``c3 = cos(uptilt) b1 + sin(uptilt) b3``), as FPV
        cameras are mounted for forward flight, in which the vehicle pitches nose down. Other
        fields as :class:`Camera` (``half_fov``, ``range``...); not ``R_BC``, which ``front``
        sets (build ``Camera(R_BC=...)`` for another mounting)."""
        if "R_BC" in kwargs:
            raise ConfigError("camera.R_BC", "is set by Camera.front (the front mounting tilted up by uptilt); "
                                             "build Camera(R_BC=...) for another mounting")
        v.keywords("camera", cls, tuple(f.name for f in fields(cls) if f.init and f.name != "R_BC"), kwargs, ("uptilt",))
        th = v.finite_float("camera.uptilt", uptilt)
        if not abs(th) < math.pi / 2:
            raise ConfigError("camera.uptilt", f"must be in (-pi/2, pi/2) rad, got {th}")
        c, s = math.cos(th), math.sin(th)
        tilt = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # about b2: b1 -> c b1 + s b3
        return cls(R_BC=tilt @ FRONT_CAMERA_R_BC, **kwargs)

    @cached_property
    def axis_B(self) -> Array:
        """Optical axis ``c3`` in body coordinates (a contiguous copy of the column, made once)."""
        axis = np.ascontiguousarray(self.R_BC[:, 2])
        axis.setflags(write=False)
        return axis

    def narrowed(self, margin: float) -> Camera | None:
        """This camera with the cone the FoV rows (8) ask for with ``FovConfig.margin``.

        The row ``h/|n_d| <= -margin``, ``h = cos(half_fov)|n_d| - n_d.e_c`` (7), reads
        ``cos(angle) >= cos(half_fov) + margin`` for the angle between ``n_d`` and the optical
        axis: a cone of half-angle ``acos(cos(half_fov) + margin)``. Mounting, image rectangle and
        range are kept. ``self`` for ``margin = 0``; ``None`` when no direction meets the rows
        (``cos(half_fov) + margin >= 1``)."""
        cos_half = math.cos(self.half_fov)
        c = cos_half + v.nonnegative_float("fov.margin", margin)
        if c >= 1.0:
            return None
        if c <= cos_half:  # margin 0, or below the float spacing of cos
            return self
        return replace(self, half_fov=min(math.acos(c), self.half_fov))

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
