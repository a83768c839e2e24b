"""Decision-vector layout: the only place with index arithmetic.

The decision vector stacks, for each flat output (x, y, z, yaw) and segment, the
``N + 1`` **normalised** coefficients ``c_hat_k = c_k T_i^k`` of ``p_i(u) = sum_k c_hat_k u^k``
with ``u = (t - t_i)/T_i`` in ``[0, 1]`` (normalised time keeps the constraint
matrix well scaled). Column of ``(axis, segment, k)`` is ``(axis * S + segment) * (N + 1) + k``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import numpy.typing as npt

from .. import _avp_rust
from .._typing import Array
from ..errors import ConfigError

N_AXES = 4
"""x, y, z, yaw."""
YAW = 3


@dataclass(frozen=True)
class DecisionLayout:
    n_segments: int
    degree: int

    @property
    def n_coeffs(self) -> int:
        return self.degree + 1

    @property
    def n_variables(self) -> int:
        return N_AXES * self.n_segments * self.n_coeffs

    def start(self, axis: int, segment: int) -> int:
        """First column of ``(axis, segment)``."""
        return (axis * self.n_segments + segment) * self.n_coeffs

    @cached_property
    def falling(self) -> Array:
        """``falling[r, k] = k!/(k-r)!`` (0 for ``k < r``), orders 0..N."""
        n = self.n_coeffs
        out = np.zeros((n, n))
        for r in range(n):
            for k in range(r, n):
                out[r, k] = np.prod(np.arange(k - r + 1, k + 1, dtype=float))
        return out

    @cached_property
    def endpoint_basis(self) -> tuple[Array, Array]:
        """``(B0, B1)``: ``B0[r]`` / ``B1[r]`` are the order-``r`` basis rows at ``u = 0`` / ``u = 1``."""
        B0 = np.diag(self.falling.diagonal()).copy()  # d^r/du^r u^k at 0 is r! delta_kr
        B1 = self.falling.copy()
        B0.setflags(write=False)
        B1.setflags(write=False)
        return B0, B1

    @cached_property
    def _exponents(self) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
        """``(powers, alive)``: ``powers[r, k] = max(k - r, 0)``, ``alive[r, k] = k >= r``."""
        k = np.arange(self.n_coeffs)
        r = k[:, None]
        return np.where(k >= r, k - r, 0), k >= r

    def basis(self, order: int, u: Array | float) -> Array:
        """Rows ``d^r/du^r u^k`` at ``u`` (shape ``(*shape(u), N + 1)``)."""
        uu = np.asarray(u, dtype=float)[..., None]
        powers, alive = self._exponents
        return self.falling[order] * np.where(alive[order], uu ** powers[order], 0.0)

    @cached_property
    def fit_nodes(self) -> Array:
        """Normalised times used to project a trajectory onto one segment (warm starts)."""
        return np.linspace(0.0, 1.0, 2 * self.n_coeffs)

    @cached_property
    def fit_pinv(self) -> Array:
        """Pseudo-inverse of the Vandermonde matrix at :attr:`fit_nodes` (ascending powers)."""
        V = self.fit_nodes[:, None] ** np.arange(self.n_coeffs)[None, :]
        return np.asarray(np.linalg.pinv(V), dtype=np.float64)

    def columns(self, axis: int | npt.NDArray[np.intp], segment: int | npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
        """Column indices of the coefficients of ``(axis, segment)`` (broadcast, last axis ``k``)."""
        start = (np.asarray(axis) * self.n_segments + np.asarray(segment)) * self.n_coeffs
        return np.asarray(start)[..., None] + np.arange(self.n_coeffs)

    def locate(self, knots_rel: Array, t: Array) -> tuple[npt.NDArray[np.intp], Array]:
        """Segment index and normalised time ``u`` of times ``t`` relative to the plan start."""
        tt = np.asarray(t, dtype=float)
        seg = np.minimum(np.maximum(np.searchsorted(knots_rel, tt, side="right") - 1, 0), self.n_segments - 1)
        u = (tt - knots_rel[seg]) / (knots_rel[seg + 1] - knots_rel[seg])
        return seg, u

    def physical_scale(self, durations: Array) -> Array:
        """``T_i^-k`` (``(S, N + 1)``): normalised coefficient ``k`` of segment ``i`` times it is
        the coefficient of ``(t - t_i)^k``."""
        return np.asarray(durations, dtype=float)[:, None] ** -np.arange(self.n_coeffs)[None, :]

    def to_physical(self, c_hat: Array, durations: Array, scale: Array | None = None) -> Array:
        """Decision vector -> ``(S, 4, N + 1)`` coefficients in powers of ``t - t_i`` (seconds).
        ``scale``: :meth:`physical_scale` of ``durations`` when the caller has it."""
        return self.physical(c_hat, self.physical_scale(durations) if scale is None else scale)[0]

    def physical(self, c_hat: Array, scale: Array) -> tuple[Array, bool]:
        """:meth:`to_physical` with the :meth:`physical_scale` ``scale``, and whether every
        coefficient is finite: one product per coefficient, by the Rust kernel
        ``physical_coefficients`` (one call, not an array operation per step)."""
        if np.ndim(c_hat) != 1:  # any shape of the right size, read in order
            c_hat = np.reshape(c_hat, -1)
        if np.shape(c_hat) != (self.n_variables,):
            raise ConfigError("c_hat", f"expected {self.n_variables} coefficients, got shape {np.shape(c_hat)}")
        if np.shape(scale) != (self.n_segments, self.n_coeffs):
            raise ConfigError("durations", f"expected {self.n_segments} segment durations (a scale of shape "
                                           f"({self.n_segments}, {self.n_coeffs})), got shape {np.shape(scale)}")
        coeffs, finite = _avp_rust.physical_coefficients(c_hat, scale)
        return coeffs, finite

    def from_physical(self, coeffs: Array, durations: Array) -> Array:
        """Inverse of :meth:`to_physical`."""
        c = np.asarray(coeffs, dtype=float).transpose(1, 0, 2)
        scale = np.asarray(durations, dtype=float)[:, None] ** np.arange(self.n_coeffs)[None, :]
        return np.asarray((c * scale[None]).reshape(-1), dtype=np.float64)


@lru_cache(maxsize=32)
def layout_for(n_segments: int, degree: int) -> DecisionLayout:
    """Shared layout instance, so its cached tables are built once per shape."""
    return DecisionLayout(n_segments, degree)
