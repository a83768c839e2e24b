"""Assemble the perching QP (5) and eliminate its equalities.

:class:`PerchingQp` keeps named constraint blocks (for diagnostics and for adding the FoV rows
(8) later). :meth:`PerchingQp.reduce` eliminates ``A c = b`` with a QR null-space basis:
``c = c_p + Z z``. The reduced QP in ``z`` has only inequalities and a positive-definite Hessian
(the initial position..jerk and yaw, yaw-rate rows pin the cost-free polynomials), and the
equalities then hold to rounding whatever the solver's tolerance.

The factorisation depends on the equality *matrix* ``A`` (durations and constraint pattern) and
the cost ``P``, not on the right-hand side ``b`` (the state and target values): it is cached per
``(A, P)`` (:data:`ELIMINATION_CACHE_SIZE` entries, found by a cheap fingerprint; when ``A`` is
stacked from the row builders' cached blocks it is itself one cached object, found by identity
without reading its entries), and only
``c_p`` and the linear cost term are recomputed for a new ``b``. Rows and cost are normalised by
the durations' scale: for equal durations (the allocation rule, every replan) by one of them
exactly, so ``A`` and ``P`` are the same bits for any total time; and a fully given contact
velocity is the world rows ``v(t_f) = R_WS v_S``, whose matrix does not depend on the pad's
frame. A replan with a re-estimated pad therefore hits the cache exactly. Otherwise (unequal
durations scaled by one factor in the time search) ``A`` and ``P`` change by rounding only: a
cached factorisation whose ``A`` and ``P`` are within :data:`REUSE_TOL` (relative, entrywise)
of the new ones is reused. Its null space then satisfies the new equalities to the same rounding
level, and the particular solution ``c_p`` is checked against the new ``A`` as always.

Rows that change with every pad (``alpha_range``'s "no ``s1``, ``s2`` thrust" and a partly free
contact velocity's ``s_i . v``, both along the pad's frame; a line perch's terminal rows) are
eliminated in a second stage inside the null space of the cached rows
(:func:`eliminate_within`, also the moving pad's elimination), so a replan whose pad estimate
moved reuses the cached factorisation and adds a QR of a few columns.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import numpy.typing as npt
import scipy.linalg
import scipy.linalg.blas
import scipy.linalg.lapack

from .. import _avp_rust
from .._typing import Array
from ..config import PlannerConfig
from ..errors import InfeasibleError
from ..trajectory import Trajectory
from ..types import PerchTarget, State
from .boundary import continuity_rows, initial_state_rows
from .cost import cost_matrix
from .layout import DecisionLayout, layout_for
from .perching import flip_rows, pre_impact_rows, terminal_parts, terminal_thrust_rows

RANK_TOL = 1e-10
"""Relative tolerance on the QR diagonal below which equality rows count as dependent."""

ELIMINATION_CACHE_SIZE = 256
"""Factorisations kept (least recently used first out); each holds a few ``n x n`` arrays."""

REUSE_TOL = 1e-13
"""Largest entrywise difference, relative to the largest entry, between a cached ``(A, P)`` and
a new one for the cached factorisation to be reused (rounding of the duration normalisation is
~1e-16 relative)."""


@dataclass(frozen=True)
class _Factor:
    """What the elimination needs from ``A`` and ``P`` alone (independent of ``b``)."""

    A: Array  # the equality matrix and cost this factor belongs to (exact-hit check)
    P: Array
    Q1: Array  # (n, rank): orthonormal basis of the row space of A
    R1: Array  # (rank, rank): triangular factor
    piv: npt.NDArray[np.intp]  # (rank,) pivoted row indices of A
    Z: Array  # (n, n - rank): null-space basis
    PZ: Array  # P @ Z
    H: Array  # scaled, symmetrised Z^T P Z
    scale: float
    G: Array  # Z^T P Z, not scaled (a further elimination inside Z starts from it)

    @cached_property
    def cholesky(self) -> Array | None:
        """:func:`cholesky_factor` of :attr:`H`, computed once per cached factorisation."""
        return cholesky_factor(self.H)


_FACTORS: OrderedDict[tuple[object, ...], list[_Factor]] = OrderedDict()
"""Buckets of factorisations by ``(shapes, fingerprints to 9 digits)``; a bucket can hold
several matrices that the fingerprint does not tell apart."""
_FACTORS_LOCK = threading.Lock()
_WEIGHTS = np.random.default_rng(0).uniform(0.5, 1.5, 1 << 16)


def _read_only(M: Array) -> Array:
    M.setflags(write=False)
    return M


_PRINTS: dict[int, tuple[Array, float]] = {}
"""Fingerprints of read-only matrices that own their data (the cached cost matrices of
:func:`avp.qp.cost.cost_matrix` and equality matrices of :func:`_stacked_matrix`), by identity;
each entry keeps its matrix alive, so an id is not reused while it is here."""


def _owned(M: Array) -> bool:
    """``M`` is read-only and owns its data: nothing writes it, so its identity fixes its values."""
    return not M.flags.writeable and M.base is None


def _cached_fingerprint(M: Array, keep: bool = True) -> float:
    """:func:`_fingerprint` of ``M``, computed once per read-only matrix object that owns its data
    (the factor's own ``hit.P is P`` and ``hit.A is A`` shortcuts rely on the same). ``keep``:
    remember a new one (the cost matrices; a stacked equality matrix is remembered only when
    :func:`_stacked_matrix` caches it, the others are used once)."""
    if not _owned(M):
        return _fingerprint(M)
    hit = _PRINTS.get(id(M))
    if hit is not None and hit[0] is M:
        return hit[1]
    value = _fingerprint(M)
    if not keep:
        return value
    if len(_PRINTS) >= 2 * ELIMINATION_CACHE_SIZE:
        _PRINTS.clear()
    _PRINTS[id(M)] = (M, value)
    return value


_STACKS: OrderedDict[tuple[int, ...], tuple[tuple[Array, ...], Array]] = OrderedDict()
"""Stacked equality matrices by the identities of their read-only blocks (least recently used
first out, :data:`ELIMINATION_CACHE_SIZE` entries); each entry keeps its blocks alive."""


def _stacked_matrix(blocks: tuple[Array, ...]) -> Array:
    """The blocks stacked (read-only). When every block is read-only and owns its data (the
    cached row builders of :mod:`avp.qp.boundary` and :mod:`avp.qp.perching`) the stack is
    cached by their identities: the QPs of a replan and of a plan's stages then share one
    equality matrix object, whose factorisation is found without comparing its entries."""
    if not all(_owned(M) for M in blocks):
        return _read_only(np.concatenate(blocks, axis=0))
    key = tuple(map(id, blocks))
    with _FACTORS_LOCK:
        hit = _STACKS.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], blocks, strict=True)):
            _STACKS.move_to_end(key)
            return hit[1]
    A = _read_only(np.concatenate(blocks, axis=0))
    _cached_fingerprint(A)
    with _FACTORS_LOCK:
        _STACKS[key] = (blocks, A)
        while len(_STACKS) > ELIMINATION_CACHE_SIZE:
            _, (_, old) = _STACKS.popitem(last=False)
            if _PRINTS.get(id(old), (None,))[0] is old:  # its fingerprint goes with it
                del _PRINTS[id(old)]
    return A


def _fingerprint(M: Array) -> float:
    """A cheap, position-sensitive checksum of ``M`` (hits are confirmed by comparison)."""
    flat = M.reshape(-1)
    n = min(flat.size, _WEIGHTS.size)
    head = float(flat[:n] @ _WEIGHTS[:n])
    # "+ 0.0" is what adding the empty tail's sum gave (it turns a -0.0 head into 0.0)
    return head + float(flat[n:].sum()) if flat.size > n else head + 0.0


def _cached_factors() -> int:
    """Number of factorisations held."""
    return sum(len(b) for b in _FACTORS.values())


def _close(M: Array, N: Array) -> bool:
    """``M`` equals ``N``, or differs by at most :data:`REUSE_TOL` relative (entrywise)."""
    if np.array_equal(M, N):
        return True
    scale = max(1.0, float(np.max(np.abs(M)))) if M.size else 1.0
    return bool(np.max(np.abs(M - N)) <= REUSE_TOL * scale)


def _factor(A: Array, P: Array) -> _Factor:
    """Pivoted QR of ``A^T`` and the reduced Hessian, cached per ``(A, P)`` up to rounding."""
    key = (A.shape, P.shape, f"{_cached_fingerprint(A, keep=False):.9e}", f"{_cached_fingerprint(P):.9e}")
    with _FACTORS_LOCK:
        for hit in _FACTORS.get(key, ()):
            if (hit.P is P or _close(hit.P, P)) and (hit.A is A or _close(hit.A, A)):
                _FACTORS.move_to_end(key)
                return hit
    Q, R, piv = scipy.linalg.qr(A.T, pivoting=True, check_finite=False)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > RANK_TOL * max(diag[0] if diag.size else 0.0, 1.0)))
    Z = Q[:, rank:]
    PZ = P @ Z
    G = Z.T @ PZ
    # Scale the objective to unit Hessian diagonal: the minimiser is unchanged and the
    # back-ends' absolute dual tolerances become meaningful (raw entries reach 1e7).
    scale = _unit_diagonal_scale(G)
    H = (0.5 * scale) * (G + G.T)
    A_kept = A if _owned(A) else A.copy()  # stacked equality matrices are read-only, cached ones shared
    P_kept = P if not P.flags.writeable else P.copy()  # the cached cost matrices are read-only
    f = _Factor(A_kept, P_kept, Q[:, :rank], R[:rank, :rank], piv[:rank], Z, PZ, H, scale, G)
    for arr in (f.A, f.P, f.Q1, f.R1, f.piv, f.Z, f.PZ, f.H, f.G):
        arr.setflags(write=False)
    with _FACTORS_LOCK:
        _FACTORS.setdefault(key, []).append(f)
        _FACTORS.move_to_end(key)
        while _cached_factors() > ELIMINATION_CACHE_SIZE:
            oldest = next(iter(_FACTORS))
            _FACTORS[oldest].pop(0)
            if not _FACTORS[oldest]:
                del _FACTORS[oldest]
    return f


def _particular(f: _Factor, b: Array) -> Array:
    """A solution of ``A c = b`` on the rank-revealing basis of ``f`` (dependent rows are checked
    by the caller): ``R1^T y = b[piv]`` by LAPACK trtrs on ``R1`` as stored, ``c = Q1 y``. Not
    :func:`_solve_transposed_upper`: for the C-ordered ``R1`` that solves the transposed system,
    other arithmetic, and every one-stage plan keeps the values it had."""
    y, info = scipy.linalg.lapack.dtrtrs(f.R1, b[f.piv], lower=0, trans=1)
    if info != 0:
        raise InfeasibleError(f"the equality elimination failed (LAPACK trtrs info {info})")
    return np.asarray(f.Q1 @ y)


@dataclass(frozen=True)
class _Within:
    """What :func:`eliminate_within` needs from ``(Z0, G0, A_t)`` alone (not the right-hand sides)."""

    Z0: Array  # the arrays this entry belongs to (kept alive: their identities are in the key)
    G0: Array
    A_t: Array
    B: Array  # A_t Z0
    Q1: Array  # (n0, rank): orthonormal basis of the row space of B
    R1: Array  # (rank, rank)
    piv: npt.NDArray[np.intp]
    Z1: Array  # null space of B
    Z: Array  # Z0 Z1
    G: Array  # Z1^T G0 Z1, not scaled

    @cached_property
    def scaled(self) -> tuple[float, Array]:
        """``(scale, H)``: ``1 / max |G_ii|`` and the Hessian ``(0.5 scale) (G + G^T)`` without
        a slip cost (read-only), computed once per entry."""
        scale = _unit_diagonal_scale(self.G)
        H = (0.5 * scale) * (self.G + self.G.T)
        H.setflags(write=False)
        return scale, H

    @cached_property
    def cholesky(self) -> Array | None:
        """:func:`cholesky_factor` of the scaled Hessian of :attr:`scaled`, computed once per entry."""
        return cholesky_factor(self.scaled[1])


_WITHIN: OrderedDict[tuple[object, ...], _Within] = OrderedDict()
"""Second-stage factorisations by ``(id(Z0), id(G0), A_t's shape and bytes)``, least recently
used first out (:data:`ELIMINATION_CACHE_SIZE` entries)."""


def _pivoted_qr(M: Array) -> tuple[Array, Array, npt.NDArray[np.intp]]:
    """``Q`` (full), the first ``min(rows, cols)`` rows of ``R`` and the pivots of
    ``scipy.linalg.qr(M, pivoting=True)``, by its LAPACK routines (geqp3, orgqr) called directly,
    without the wrapper's overhead (the same values at this module's sizes)."""
    rows, cols = M.shape
    if rows == 0 or cols == 0:  # LAPACK rejects empty matrices
        return np.eye(rows), np.zeros((0, cols)), np.arange(cols)
    qr, jpvt, tau, _, info = scipy.linalg.lapack.dgeqp3(np.asfortranarray(M))
    if info != 0:  # pragma: no cover - LAPACK argument errors only
        raise InfeasibleError(f"the equality elimination failed (LAPACK geqp3 info {info})")
    a = np.zeros((rows, rows), order="F")
    a[:, :cols] = qr[:, :rows] if cols > rows else qr
    Q, _, info = scipy.linalg.lapack.dorgqr(a, tau)
    if info != 0:  # pragma: no cover
        raise InfeasibleError(f"the equality elimination failed (LAPACK orgqr info {info})")
    return Q, np.triu(qr[:min(rows, cols), :]), jpvt - 1


def _solve_transposed_upper(R: Array, b: Array) -> Array:
    """``y`` with ``R^T y = b`` for an upper triangular ``R``: LAPACK trtrs called as
    ``scipy.linalg.solve_triangular(R, b, trans="T")`` calls it (a C-ordered ``R`` as the lower
    triangular ``R^T`` in Fortran order), so the same values, without the wrapper's overhead."""
    if R.size == 0:
        return np.zeros(0)
    if R.flags.f_contiguous:
        y, info = scipy.linalg.lapack.dtrtrs(R, b, lower=0, trans=1)
    else:
        y, info = scipy.linalg.lapack.dtrtrs(R.T, b, lower=1, trans=0)
    if info != 0:
        raise InfeasibleError(f"the equality elimination failed (LAPACK trtrs info {info})")
    return np.asarray(y)


def _within(Z0: Array, G0: Array, A_t: Array, cache: bool) -> _Within:
    """The second-stage factorisation of :func:`eliminate_within`, cached per ``(Z0, G0, A_t)``
    when ``cache`` (``Z0`` and ``G0`` by identity: the callers' cached arrays; ``A_t`` by its
    bytes)."""
    key = (id(Z0), id(G0), A_t.shape, A_t.tobytes()) if cache else None
    if key is not None:
        with _FACTORS_LOCK:
            hit = _WITHIN.get(key)
            if hit is not None and hit.Z0 is Z0 and hit.G0 is G0:
                _WITHIN.move_to_end(key)
                return hit
    B = A_t @ Z0
    Q, R, piv = _pivoted_qr(B.T)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > RANK_TOL * max(float(diag[0]) if diag.size else 0.0, 1.0)))
    Z1 = Q[:, rank:]
    w = _Within(Z0, G0, A_t.copy(), B, Q[:, :rank], R[:rank, :rank], piv[:rank], Z1, Z0 @ Z1, Z1.T @ G0 @ Z1)
    for arr in (w.A_t, w.B, w.Q1, w.R1, w.piv, w.Z1, w.Z, w.G):
        arr.setflags(write=False)
    if key is not None:
        with _FACTORS_LOCK:
            _WITHIN[key] = w
            _WITHIN.move_to_end(key)
            while len(_WITHIN) > ELIMINATION_CACHE_SIZE:
                _WITHIN.popitem(last=False)
    return w


_TERMINAL_INCONSISTENT = "the terminal equalities are inconsistent (residual {:.2e}); raise config.n_segments or config.degree"
_INCONSISTENT = ("the equality constraints are inconsistent (residual {:.2e}): the spline has too few degrees of "
                 "freedom; raise config.n_segments or config.degree")


def eliminate_within(Z0: Array, c0: Array, G0: Array, P: Array, A_t: Array, b_t: Array,
                     M: Array | None = None, inconsistent: str = _TERMINAL_INCONSISTENT, cache: bool = True,
                     ) -> tuple[Array, Array, Array, Array]:
    """The second stage of a two-stage elimination: ``c = c0 + Z0 w`` spans the solutions of
    some equalities (``G0 = Z0^T P Z0``); the rows ``A_t c = b_t`` are eliminated inside that
    null space (a QR of ``(A_t Z0)^T``, a few columns, instead of the whole ``A``; cached per
    ``(Z0, G0, A_t)`` unless ``cache`` is false, :func:`_within`: rows that change at every
    call, a moving pad's, would only push out the others). Returns :attr:`PerchingQp.elimination`'s
    ``(Z, c_p, H, g)`` for the cost ``P + M^T M`` (``M``: :mod:`avp.qp.moving`'s slip cost),
    scaled to a unit largest Hessian diagonal.

    Raises :class:`InfeasibleError` (``inconsistent``, formatted with the residual) when the rows
    ``A_t`` cannot be met inside the null space.
    """
    return _eliminate_within(Z0, c0, G0, P, A_t, b_t, M, inconsistent, cache)[:4]


def _eliminate_within(Z0: Array, c0: Array, G0: Array, P: Array, A_t: Array, b_t: Array, M: Array | None,
                      inconsistent: str, cache: bool) -> tuple[Array, Array, Array, Array, _Within | None]:
    """:func:`eliminate_within`, and the entry whose cached Hessian it returned (``None`` with a
    slip cost ``M``: the Hessian is then computed here)."""
    w = _within(Z0, G0, A_t, cache)
    rhs = b_t - A_t @ c0
    w_p = w.Q1 @ _solve_transposed_upper(w.R1, rhs[w.piv])
    residual = float(np.max(np.abs(w.B @ w_p - rhs)))
    if residual > 1e-8 * max(1.0, float(np.max(np.abs(b_t)))):
        raise InfeasibleError(inconsistent.format(residual))
    Z = w.Z
    c_p = c0 + Z0 @ w_p
    Pc = P @ c_p
    if M is None:  # the cost's Hessian in the null space, scaled, is the cached entry's
        scale, H = w.scaled
        return Z, c_p, H, scale * (Z.T @ Pc), w
    MZ = M @ Z
    H = w.G + MZ.T @ MZ
    Pc = Pc + M.T @ (M @ c_p)
    scale = _unit_diagonal_scale(H)
    return Z, c_p, (0.5 * scale) * (H + H.T), scale * (Z.T @ Pc), None


def cholesky_factor(H: Array) -> Array | None:
    """``R`` (upper triangular, Fortran-ordered, read-only) with ``H = R^T R``, by LAPACK potrf on
    the upper triangle of the symmetric ``H``; ``None`` when ``H`` is empty or potrf finds it not
    positive definite.

    With ``u = R z`` the reduced QP ``min 1/2 z^T H z + g^T z`` s.t. ``lower <= G z <= upper``
    is the least-distance problem ``min 1/2 |u|^2 + (R^-T g)^T u`` s.t. ``lower <= G R^-1 u <=
    upper`` (:class:`LeastDistanceQp`): DAQP's own form (Arnström, Bemporad and Axehill, "A
    dual active-set solver for embedded quadratic programming using recursive LDL^T updates"),
    which it otherwise builds from ``H`` at every call."""
    if H.size == 0:
        return None
    R, info = scipy.linalg.lapack.dpotrf(H, lower=0, clean=1)
    if info != 0 or not np.isfinite(R).all():
        return None
    return _read_only(R)


def _solve_upper(R: Array, b: Array, transposed: bool = False) -> Array:
    """``x`` with ``R x = b`` (``R^T x = b`` when ``transposed``) for the upper triangular,
    nonsingular ``R`` of :func:`cholesky_factor` (BLAS trsv)."""
    return np.asarray(scipy.linalg.blas.dtrsv(R, b, lower=0, trans=int(transposed)))


@dataclass(frozen=True)
class LeastDistanceQp:
    """The reduced QP in ``u = R z`` (:func:`cholesky_factor`): ``min 1/2 |u|^2 + v^T u`` s.t.
    ``lower <= M u <= upper`` (the reduced QP's bounds). ``M`` and ``v`` are computed by
    triangular solves (``M R = G``, ``R^T v = g``), not through ``R^-1``, and ``M`` is shared with
    the copies of its QP: a row-major, writable buffer (DAQP takes no other) that nothing may
    write."""

    R: Array
    M: Array  # G R^-1
    v: Array  # R^-T g

    def reduced(self, u: Array) -> Array:
        """``z = R^-1 u`` (the reduced QP's variable)."""
        return _solve_upper(self.R, u)


def _rows_over(R: Array, G: Array) -> Array:
    """``G R^-1``, row-major and writable, by a triangular solve (BLAS trsm: ``R^T X = G^T``
    on the column-major view ``G^T``, and ``X^T`` is row-major)."""
    if G.shape[0] == 0:
        return np.zeros((0, R.shape[0]))
    return np.asarray(scipy.linalg.blas.dtrsm(1.0, R, G.T, side=0, lower=0, trans_a=1).T)


def _unit_diagonal_scale(H: Array) -> float:
    """``1 / max |H_ii|`` (1 for an empty ``H``; at most ``1e300``): the cost's scale to a unit
    largest Hessian diagonal."""
    return 1.0 / max(float(np.max(np.abs(np.diag(H)))) if H.size else 1.0, 1e-300)


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

    @cached_property
    def knots_rel(self) -> Array:
        return _read_only(np.concatenate([[0.0], np.cumsum(self.durations)]))

    def stacked_equalities(self) -> tuple[Array, Array]:
        """``(A, b)`` of all equality blocks (stacked once per QP, read-only; ``A`` may be shared
        by other QPs and the elimination cache: never make it writable)."""
        return self._stacked_equalities

    def stacked_inequalities(self) -> tuple[Array, Array, Array]:
        """``(G, lower, upper)`` of all inequality blocks (stacked once per QP, read-only)."""
        return self._stacked_inequalities

    @cached_property
    def _stacked_equalities(self) -> tuple[Array, Array]:
        A = _stacked_matrix(tuple(b.matrix for b in self.equalities))
        b = np.concatenate([b.lower for b in self.equalities])
        return A, _read_only(b)

    @cached_property
    def _stacked_inequalities(self) -> tuple[Array, Array, Array]:
        n = self.layout.n_variables
        if self._filled_from_parent():
            return self.__dict__["_stacked_inequalities"]  # type: ignore[no-any-return]
        parent = self.__dict__.get("_parent")
        if parent is not None and "_stacked_inequalities" in parent.__dict__:
            # a copy with more blocks: the parent's stacked rows, then the new blocks
            G0, lo0, hi0 = parent._stacked_inequalities
            new = self.inequalities[len(parent.inequalities):]
            return (
                _read_only(np.concatenate([G0, *(b.matrix for b in new)], axis=0)),
                _read_only(np.concatenate([lo0, *(b.lower for b in new)])),
                _read_only(np.concatenate([hi0, *(b.upper for b in new)])),
            )
        if not self.inequalities:
            return _read_only(np.zeros((0, n))), _read_only(np.zeros(0)), _read_only(np.zeros(0))
        return (
            _read_only(np.concatenate([b.matrix for b in self.inequalities], axis=0)),
            _read_only(np.concatenate([b.lower for b in self.inequalities])),
            _read_only(np.concatenate([b.upper for b in self.inequalities])),
        )

    @cached_property
    def _increasing(self) -> bool:
        """Whether :attr:`knots_rel` increases strictly (the trajectory's own check)."""
        k = self.knots_rel.tolist()
        return all(map(float.__lt__, k[:-1], k[1:]))

    @cached_property
    def _physical_scale(self) -> Array:
        """``T_i^-k`` per segment and power (:meth:`DecisionLayout.to_physical`), read-only."""
        return _read_only(self.layout.physical_scale(self.durations))

    def trajectory(self, c_hat: Array, g: float) -> Trajectory:
        """The :class:`~avp.trajectory.Trajectory` of normalised coefficients ``c_hat``, starting
        at ``t0`` with this QP's durations."""
        coeffs, finite = self.layout.physical(c_hat, self._physical_scale)
        if not (self._increasing and finite):
            return Trajectory(coeffs, self.t0 + self.knots_rel, g=g)  # raises the typed error
        return Trajectory._trusted(coeffs, self.t0, self.knots_rel, g)

    def with_inequalities(self, *blocks: ConstraintBlock) -> PerchingQp:
        """A copy with more inequality blocks (e.g. the FoV rows (8) and trust region (9)); its
        stacked and reduced rows reuse this QP's when computed (only the new blocks are added)."""
        other = self._same_equalities(replace(self, inequalities=self.inequalities + tuple(blocks)))
        other.__dict__["_parent"] = self
        return other

    def without(self, name_prefix: str) -> PerchingQp:
        """A copy without the inequality blocks whose name starts with ``name_prefix``."""
        kept = tuple(b for b in self.inequalities if not b.name.startswith(name_prefix))
        return self._same_equalities(replace(self, inequalities=kept))

    def _same_equalities(self, other: PerchingQp) -> PerchingQp:
        """``other`` has this QP's cost and equalities: hand over the elimination if computed."""
        for name in ("elimination", "_hessian_owner", "_cholesky", "_stacked_equalities", "knots_rel", "_increasing",
                     "_physical_scale"):
            if name in self.__dict__:
                other.__dict__[name] = self.__dict__[name]
        return other

    @cached_property
    def elimination(self) -> tuple[Array, Array, Array, Array]:
        """``(Z, c_p, H, g)``: ``A c = b`` iff ``c = c_p + Z z`` (pivoted QR of ``A^T``), and the
        cost in ``z``, scaled to a unit largest Hessian diagonal. Shared by copies made with
        :meth:`with_inequalities` / :meth:`without` (same cost and equalities).

        When some equality blocks are cached (read-only, own their data) and others are not
        (the terminal rows in the pad's frame: ``alpha_range``, a partly free contact
        velocity), the cached ones are eliminated first, from their cached factorisation, and
        the others inside its null space (:func:`eliminate_within`): a re-estimated pad then
        costs a QR of a few columns, not of the whole ``A``.

        Raises :class:`InfeasibleError` when the equalities are inconsistent (more independent
        conditions than the spline can meet).
        """
        A, b = self.stacked_equalities()
        m = A.shape[0]
        blocks = tuple(blk for blk in self.equalities if blk.n_rows)
        fixed = tuple(blk for blk in blocks if _owned(blk.matrix))
        if fixed and len(fixed) < len(blocks):
            # Some rows change from QP to QP (the pad's frame): eliminate the cached rows first,
            # from their cached factorisation, then the others inside its null space.
            A1 = _stacked_matrix(tuple(blk.matrix for blk in fixed))
            f = _factor(A1, self.P)
            c0 = _particular(f, np.concatenate([blk.lower for blk in fixed]))
            rest = tuple(blk for blk in blocks if not _owned(blk.matrix))
            Z, c_p, H, g, owner = _eliminate_within(f.Z, c0, f.G, self.P, np.concatenate([blk.matrix for blk in rest]),
                                                    np.concatenate([blk.lower for blk in rest]), None, _INCONSISTENT, True)
            self.__dict__["_hessian_owner"] = owner
        else:
            f = _factor(A, self.P)
            c_p = _particular(f, b)
            Z, H, g = f.Z, f.H, f.scale * (f.PZ.T @ c_p)
            self.__dict__["_hessian_owner"] = f
        residual = float(np.abs(A @ c_p - b).max()) if m else 0.0
        if residual > 1e-8 * max(1.0, float(np.abs(b).max()) if m else 0.0):
            raise InfeasibleError(_INCONSISTENT.format(residual))
        return Z, c_p, H, g

    def reduce(self) -> ReducedQp:
        """The QP in ``z`` (see :attr:`elimination`): only inequalities, positive-definite Hessian.
        Computed once per QP; a copy made by :meth:`with_inequalities` reduces only its new rows
        when this QP's reduction exists."""
        return self._reduced

    def least_distance(self) -> LeastDistanceQp | None:
        """The reduced QP as a least-distance problem (:class:`LeastDistanceQp`), or ``None``
        when its Hessian has no Cholesky factor or the transformed rows overflow. Computed once
        per QP; a copy made by :meth:`with_inequalities` transforms only its new rows when this
        QP's exists, and copies with this QP's equalities share its factor."""
        return self._least_distance

    @cached_property
    def _cholesky(self) -> Array | None:
        """:func:`cholesky_factor` of the reduced Hessian: the cached factorisation's own when
        the Hessian is one (``_hessian_owner``, set by :attr:`elimination`), computed here
        otherwise; handed to copies with the same equalities (:meth:`_same_equalities`)."""
        H = self.elimination[2]
        owner = self.__dict__.get("_hessian_owner")
        return owner.cholesky if owner is not None else cholesky_factor(H)

    @cached_property
    def _least_distance(self) -> LeastDistanceQp | None:
        R = self._cholesky
        if R is None:
            return None
        if self._filled_from_parent():
            return self.__dict__["_least_distance"]  # type: ignore[no-any-return]
        red = self._reduced
        parent = self.__dict__.get("_parent")
        if parent is not None and parent.__dict__.get("_least_distance") is not None:
            p = parent._least_distance
            k = p.M.shape[0]
            if p.R is R and parent._reduced.g is red.g and k <= red.G.shape[0]:
                if k == red.G.shape[0]:
                    return LeastDistanceQp(R, p.M, p.v)
                new = _rows_over(R, red.G[k:])
                return LeastDistanceQp(R, np.concatenate([p.M, new], axis=0), p.v) if np.isfinite(new).all() else None
        M, v = _rows_over(R, red.G), _solve_upper(R, red.g, transposed=True)
        if not (np.isfinite(M).all() and np.isfinite(v).all()):  # a nearly singular factor: DAQP gets the QP in z
            return None
        return LeastDistanceQp(R, M, v)

    def _filled_from_parent(self) -> bool:
        """For a copy with more blocks (:meth:`with_inequalities`) of a QP whose stacked, reduced
        and least-distance rows all exist (a QP solved by DAQP in the reduced form, as every SQP
        step's base is), and before any of the copy's own: fills the copy's three, the new rows
        appended, by one kernel call (``avp._avp_rust.append_rows``) instead of a dozen NumPy
        calls, and returns ``True``; ``False`` otherwise (the properties then compute theirs one
        by one). The caller is one of the three cached properties, which then reads its own.
        The new rows' products are the kernel's (left-to-right sums, a forward substitution), so
        they can differ from BLAS's in the last bits. A parent without a least-distance form
        (no factor, or rows that overflowed it) gives the copy none either: the copy's factor is
        its parent's (:meth:`_same_equalities`), and its rows include the parent's."""
        d = self.__dict__
        parent = d.get("_parent")
        if parent is None or "_reduced" in d or "_least_distance" in d or "_stacked_inequalities" in d:
            return False
        pd = parent.__dict__
        if not ("_stacked_inequalities" in pd and "_reduced" in pd and "_least_distance" in pd):
            return False
        new = self.inequalities[len(parent.inequalities):]
        Z, c_p, H, g = self.elimination
        r0: ReducedQp = pd["_reduced"]
        p: LeastDistanceQp | None = pd["_least_distance"]
        if not new or r0.Z is not Z or r0.g is not g or (p is not None and p.R is not self._cholesky):
            return False
        G0, lo0, hi0 = pd["_stacked_inequalities"]
        G, lo, hi, Gz, lo_z, hi_z, M = _avp_rust.append_rows(  # reads any layout (Z, R are Fortran-ordered)
            G0, lo0, hi0, r0.G, r0.lower, r0.upper, None if p is None else p.M,
            [(b.matrix, b.lower, b.upper) for b in new], Z, c_p, None if p is None else p.R)
        d["_stacked_inequalities"] = (_read_only(G), _read_only(lo), _read_only(hi))
        d["_reduced"] = ReducedQp(H=H, g=g, G=Gz, lower=lo_z, upper=hi_z, Z=Z, c_p=c_p)
        d["_least_distance"] = None if p is None or M is None else LeastDistanceQp(p.R, M, p.v)
        return True

    @cached_property
    def _reduced(self) -> ReducedQp:
        if self._filled_from_parent():
            return self.__dict__["_reduced"]  # type: ignore[no-any-return]
        Z, c_p, H, g = self.elimination
        parent = self.__dict__.get("_parent")
        if parent is not None and "_reduced" in parent.__dict__:
            r0 = parent._reduced
            new = self.inequalities[len(parent.inequalities):]
            if new:
                k = r0.G.shape[0]
                if "_stacked_inequalities" in self.__dict__:  # the new rows are already stacked: views
                    G_all, lo_all, hi_all = self._stacked_inequalities
                    Gn, lo_n, hi_n = G_all[k:], lo_all[k:], hi_all[k:]
                else:
                    Gn = np.concatenate([b.matrix for b in new], axis=0)
                    lo_n, hi_n = np.concatenate([b.lower for b in new]), np.concatenate([b.upper for b in new])
                Gc = Gn @ c_p
                return ReducedQp(H=H, g=g, G=np.concatenate([r0.G, Gn @ Z], axis=0),
                                 lower=np.concatenate([r0.lower, lo_n - Gc]), upper=np.concatenate([r0.upper, hi_n - Gc]),
                                 Z=Z, c_p=c_p)
            return replace(r0)
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
    knots_rel = np.concatenate(((0.0,), T.cumsum()))
    # equal durations (every replan) scale by one of them exactly: the rows, which depend on
    # T_i / t_scale, are then the same bits at every step and hit the elimination cache exactly
    t_scale = float(T[0]) if T.min() == T.max() else float(T.mean())
    P = cost_matrix(layout, T, config.position_cost_order, config.yaw_cost_order)
    A0, b0 = initial_state_rows(layout, T, state, t_scale)
    Ac = continuity_rows(layout, T, config.continuity_order, t_scale)
    (At, bt, _), (Ap, bp, _) = terminal_parts(layout, knots_rel, target, config, state.yaw, t_scale, T_last=float(T[-1]))
    eq: tuple[ConstraintBlock, ...] = (
        ConstraintBlock("initial state", A0, b0, b0),
        ConstraintBlock("continuity", Ac, np.zeros(Ac.shape[0]), np.zeros(Ac.shape[0])),
        ConstraintBlock("terminal", At, bt, bt),
    )
    if Ap.shape[0]:  # rows along the pad's frame (alpha_range, a partly free contact velocity)
        eq += (ConstraintBlock("terminal, in the pad's frame", Ap, bp, bp),)
    G, lo, hi = pre_impact_rows(layout, knots_rel, target, config)
    ineq: tuple[ConstraintBlock, ...] = (ConstraintBlock("pre-impact band (14)", G, lo, hi),) if G.shape[0] else ()
    Ga, la, ha = terminal_thrust_rows(layout, knots_rel, target, config)
    if Ga.shape[0]:
        ineq += (ConstraintBlock("contact thrust range (12)", Ga, la, ha),)
    Gf, lf, hf = flip_rows(layout, knots_rel, target, config)
    if Gf.shape[0]:
        ineq += (ConstraintBlock("overhang flip: thrust through the horizontal", Gf, lf, hf),)
    qp = PerchingQp(layout=layout, durations=T, t0=state.time, P=P, equalities=eq, inequalities=ineq)
    qp.__dict__["knots_rel"] = _read_only(knots_rel)  # the same values as the property computes
    return qp
