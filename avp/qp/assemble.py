"""Assemble the perching QP (5) and eliminate its equalities.

:class:`PerchingQp` keeps named constraint blocks (for diagnostics and for adding the FoV rows
(8) later). :meth:`PerchingQp.reduce` eliminates ``A c = b`` with a QR null-space basis:
``c = c_p + Z z``. The reduced QP in ``z`` has only inequalities and a positive-definite Hessian
(the initial position..jerk and yaw, yaw-rate rows pin the cost-free polynomials), and the
equalities then hold to rounding whatever the solver's tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import numpy.typing as npt
import scipy.linalg

from ..config import PlannerConfig
from ..errors import InfeasibleError
from ..trajectory import Trajectory
from ..types import PerchTarget, State
from .boundary import continuity_rows, initial_state_rows
from .cost import cost_matrix
from .layout import DecisionLayout, layout_for
from .perching import flip_rows, pre_impact_rows, terminal_rows, terminal_thrust_rows

Array = npt.NDArray[np.float64]

RANK_TOL = 1e-10
"""Relative tolerance on the QR diagonal below which equality rows count as dependent."""


@dataclass(frozen=True)
class ConstraintBlock:
    """Rows ``lower <= matrix @ c_hat <= upper`` (``lower == upper`` for equalities)."""

    name: str
    matrix: Array
    lower: Array
    upper: Array

    @property
    def n_rows(self) -> int:
        return int(self.matrix.shape[0])


@dataclass(frozen=True)
class ReducedQp:
    """``min 1/2 z^T H z + g^T z`` s.t. ``lower <= G z <= upper``, with ``c_hat = c_p + Z z``."""

    H: Array
    g: Array
    G: Array
    lower: Array
    upper: Array
    Z: Array
    c_p: Array

    def lift(self, z: Array) -> Array:
        return self.c_p + self.Z @ z


@dataclass(frozen=True)
class PerchingQp:
    """The QP (5) of one plan in normalised coefficients (see :mod:`avp.qp.layout`)."""

    layout: DecisionLayout
    durations: Array
    t0: float
    P: Array
    equalities: tuple[ConstraintBlock, ...]
    inequalities: tuple[ConstraintBlock, ...] = field(default=())

    @property
    def knots_rel(self) -> Array:
        return np.concatenate([[0.0], np.cumsum(self.durations)])

    def stacked_equalities(self) -> tuple[Array, Array]:
        A = np.vstack([b.matrix for b in self.equalities])
        return A, np.concatenate([b.lower for b in self.equalities])

    def stacked_inequalities(self) -> tuple[Array, Array, Array]:
        n = self.layout.n_variables
        if not self.inequalities:
            return np.zeros((0, n)), np.zeros(0), np.zeros(0)
        return (
            np.vstack([b.matrix for b in self.inequalities]),
            np.concatenate([b.lower for b in self.inequalities]),
            np.concatenate([b.upper for b in self.inequalities]),
        )

    def trajectory(self, c_hat: Array, g: float) -> Trajectory:
        """The :class:`~avp.trajectory.Trajectory` of normalised coefficients ``c_hat``, starting
        at ``t0`` with this QP's durations."""
        coeffs = self.layout.to_physical(c_hat, self.durations)
        return Trajectory(coeffs, self.t0 + self.knots_rel, g=g)

    def with_inequalities(self, *blocks: ConstraintBlock) -> PerchingQp:
        """A copy with more inequality blocks (e.g. the FoV rows (8) and trust region (9))."""
        return self._same_equalities(replace(self, inequalities=self.inequalities + tuple(blocks)))

    def without(self, name_prefix: str) -> PerchingQp:
        """A copy without the inequality blocks whose name starts with ``name_prefix``."""
        kept = tuple(b for b in self.inequalities if not b.name.startswith(name_prefix))
        return self._same_equalities(replace(self, inequalities=kept))

    def _same_equalities(self, other: PerchingQp) -> PerchingQp:
        """``other`` has this QP's cost and equalities: hand over the elimination if computed."""
        if "elimination" in self.__dict__:
            other.__dict__["elimination"] = self.__dict__["elimination"]
        return other

    @cached_property
    def elimination(self) -> tuple[Array, Array, Array, Array]:
        """``(Z, c_p, H, g)``: ``A c = b`` iff ``c = c_p + Z z`` (pivoted QR of ``A^T``), and the
        cost in ``z``, scaled to a unit largest Hessian diagonal. Shared by copies made with
        :meth:`with_inequalities` / :meth:`without` (same cost and equalities).

        Raises :class:`InfeasibleError` when the equalities are inconsistent (more independent
        conditions than the spline can meet).
        """
        A, b = self.stacked_equalities()
        m = A.shape[0]
        Q, R, piv = scipy.linalg.qr(A.T, pivoting=True, check_finite=False)
        diag = np.abs(np.diag(R))
        rank = int(np.sum(diag > RANK_TOL * max(diag[0] if diag.size else 0.0, 1.0)))
        # Particular solution on the rank-revealing basis; dependent rows must then agree.
        y = scipy.linalg.solve_triangular(R[:rank, :rank], b[piv[:rank]], trans="T", check_finite=False)
        c_p = Q[:, :rank] @ y
        residual = float(np.max(np.abs(A @ c_p - b))) if m else 0.0
        if residual > 1e-8 * max(1.0, float(np.max(np.abs(b)))):
            raise InfeasibleError(
                f"the equality constraints are inconsistent (residual {residual:.2e}): the spline has "
                f"too few degrees of freedom; raise config.n_segments or config.degree"
            )
        Z = Q[:, rank:]
        PZ = self.P @ Z
        H = Z.T @ PZ
        # Scale the objective to unit Hessian diagonal: the minimiser is unchanged and the
        # back-ends' absolute dual tolerances become meaningful (raw entries reach 1e7).
        scale = 1.0 / max(float(np.max(np.abs(np.diag(H)))) if H.size else 1.0, 1e-300)
        H = (0.5 * scale) * (H + H.T)
        g = scale * (PZ.T @ c_p)
        return Z, c_p, H, g

    def reduce(self) -> ReducedQp:
        """The QP in ``z`` (see :attr:`elimination`): only inequalities, positive-definite Hessian."""
        Z, c_p, H, g = self.elimination
        G, lo, hi = self.stacked_inequalities()
        Gc = G @ c_p
        return ReducedQp(H=H, g=g, G=G @ Z, lower=lo - Gc, upper=hi - Gc, Z=Z, c_p=c_p)


def build_perching_qp(
    state: State,
    target: PerchTarget,
    config: PlannerConfig,
    durations: Array,
) -> PerchingQp:
    """The perching QP: cost (4), initial state, continuity, terminal (12)/(13), band (14)."""
    layout = layout_for(config.n_segments, config.degree)
    T = np.asarray(durations, dtype=float)
    knots_rel = np.concatenate([[0.0], np.cumsum(T)])
    t_scale = float(T.mean())
    P = cost_matrix(layout, T, config.position_cost_order, config.yaw_cost_order)
    A0, b0 = initial_state_rows(layout, T, state, t_scale)
    Ac = continuity_rows(layout, T, config.continuity_order, t_scale)
    At, bt, _names = terminal_rows(layout, knots_rel, target, config, state.yaw, t_scale)
    eq = (
        ConstraintBlock("initial state", A0, b0, b0),
        ConstraintBlock("continuity", Ac, np.zeros(Ac.shape[0]), np.zeros(Ac.shape[0])),
        ConstraintBlock("terminal", At, bt, bt),
    )
    G, lo, hi = pre_impact_rows(layout, knots_rel, target, config)
    ineq: tuple[ConstraintBlock, ...] = (ConstraintBlock("pre-impact band (14)", G, lo, hi),) if G.shape[0] else ()
    Ga, la, ha = terminal_thrust_rows(layout, knots_rel, target, config)
    if Ga.shape[0]:
        ineq += (ConstraintBlock("contact thrust range (12)", Ga, la, ha),)
    Gf, lf, hf = flip_rows(layout, knots_rel, target, config)
    if Gf.shape[0]:
        ineq += (ConstraintBlock("overhang flip: thrust through the horizontal", Gf, lf, hf),)
    return PerchingQp(layout=layout, durations=T, t0=state.time, P=P, equalities=eq, inequalities=ineq)
