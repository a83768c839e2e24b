"""QP assembly for one perching plan, eq. (5): cost (4), boundary and continuity equalities,
perching constraints (12)-(14). Python owns this; the solve lives in :mod:`avp.solve`."""

from .assemble import ConstraintBlock, PerchingQp, build_perching_qp
from .layout import DecisionLayout

__all__ = ["ConstraintBlock", "DecisionLayout", "PerchingQp", "build_perching_qp"]
