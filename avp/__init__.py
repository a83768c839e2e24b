"""avp: active visual perching for quadrotors.

Plans minimum-snap perching trajectories on the flat outputs (x, y, z, yaw) after Mao et al.,
"Robust Active Visual Perching With Quadrotors on Inclined Surfaces", IEEE T-RO 2023. Equation
numbers in docstrings, such as (12), refer to that paper.
"""

from __future__ import annotations

try:
    from . import _avp_rust
except ImportError as exc:  # pragma: no cover - exercised only on a broken install
    raise ImportError(
        "avp._avp_rust is not built: install the package with `pip install .` or "
        "`pip install -e .` (needs a Rust toolchain), or run `maturin develop`"
    ) from exc

from .errors import (
    AvpError,
    BoundsNotCertifiedError,
    ConfigError,
    InfeasibleError,
    PlanningError,
    RelaxedPlanError,
    SolverError,
    WorkerError,
    WorkspaceNotCertifiedError,
)

__version__: str = _avp_rust.__version__

__all__ = [
    "AvpError",
    "BoundsNotCertifiedError",
    "ConfigError",
    "InfeasibleError",
    "PlanningError",
    "RelaxedPlanError",
    "SolverError",
    "WorkerError",
    "WorkspaceNotCertifiedError",
    "__version__",
]

from .background import BackgroundReplanner, BackgroundStep, PlanningWorker
from .bounds import Bound, BoundReport, Certificate
from .camera import Camera
from .config import (
    BoundsPolicy,
    ContactVelocity,
    FovConfig,
    FovPointPolicy,
    HalfSpace,
    OverhangFlip,
    PlannerConfig,
    PreImpactMode,
    QpForm,
    Relaxation,
    ReplanConfig,
    Sphere,
    TimeAllocation,
    TimeSearch,
    VehicleLimits,
    Workspace,
)
from .line import LineTarget, LineYaw
from .line_planner import LineOptions, LinePlanResult, LineStatus, plan_line
from .line_replan import LineReplanner
from .metrics import Visibility, visibility
from .moving import (
    MovingConfig,
    MovingPlanResult,
    MovingReplanner,
    plan_moving,
    plan_moving_detailed,
)
from .planner import PlanResult, PlanStatus, PlanTimings, plan, plan_detailed
from .platform import MotionModel, MovingTarget
from .replan import ReplanAction, Replanner, ReplanStep
from .safety import SafetyReport
from .trajectory import Derivative, FlatOutput, Provenance, Trajectory
from .types import PerchTarget, State

__all__ += [
    "BackgroundReplanner",
    "BackgroundStep",
    "Bound",
    "BoundReport",
    "BoundsPolicy",
    "Camera",
    "Certificate",
    "ContactVelocity",
    "Derivative",
    "FlatOutput",
    "FovConfig",
    "FovPointPolicy",
    "HalfSpace",
    "MotionModel",
    "MovingConfig",
    "MovingPlanResult",
    "MovingReplanner",
    "MovingTarget",
    "OverhangFlip",
    "PerchTarget",
    "PlanResult",
    "PlanStatus",
    "PlanTimings",
    "PlannerConfig",
    "PlanningWorker",
    "PreImpactMode",
    "Provenance",
    "QpForm",
    "Relaxation",
    "ReplanAction",
    "ReplanConfig",
    "ReplanStep",
    "Replanner",
    "SafetyReport",
    "Sphere",
    "State",
    "TimeAllocation",
    "TimeSearch",
    "Trajectory",
    "VehicleLimits",
    "Visibility",
    "Workspace",
    "plan",
    "plan_detailed",
    "plan_moving",
    "plan_moving_detailed",
    "visibility",
]

# Line and powerline perches (docs/lines.md)
__all__ += ["LineOptions", "LinePlanResult", "LineReplanner", "LineStatus", "LineTarget", "LineYaw", "plan_line"]

