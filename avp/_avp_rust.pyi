"""Stubs for the compiled kernels (avp_rust). Coefficients are in ascending powers."""

import numpy as np
import numpy.typing as npt

__all__ = [
    "BOUND_NAMES",
    "__version__",
    "anticipate",
    "bound_polynomial",
    "certify_below",
    "certify_below_many",
    "certify_halfspace",
    "certify_speed",
    "certify_sphere_outside",
    "certify_spline",
    "eval_spline",
    "sturm_count",
]

__version__: str

def eval_spline(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    times: npt.NDArray[np.float64],
    orders: list[int],
) -> npt.NDArray[np.float64]:
    """Spline derivatives, shape ``(len(orders), len(times), axes)``.

    ``coeffs`` has shape ``(segments, axes, coeffs)`` in powers of ``t - knots[i]``; times outside
    ``[knots[0], knots[-1]]`` extrapolate the first/last segment. Raises ``ValueError`` on bad
    shapes, non-finite values or non-increasing knots.
    """

def anticipate(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    odometry: npt.NDArray[np.float64],
    t_rp: float,
    t_ex: float,
) -> npt.NDArray[np.float64]:
    """Anticipated state (6): ``x_n^(k) + P^(k)(t_ex) - P^(k)(t_rp)``, shape ``(5, axes)``.

    ``odometry`` has shape ``(5, axes)`` (orders 0..4). Both times must lie in the plan's domain
    with ``t_ex >= t_rp``; otherwise ``ValueError``.
    """

# --- bound certificates (sturm.rs, exact.rs, certify.rs, bounds.rs) ---------------------------

BOUND_NAMES: list[str]

def sturm_count(coeffs: npt.NDArray[np.float64], a: float, b: float) -> int:
    """Exact number of distinct real roots of ``sum coeffs[k] x^k`` in the closed ``[a, b]``.

    Interval-arithmetic Sturm sequence, exact big-integer fallback when unsure. Raises
    ``ValueError`` on NaN/inf, ``a > b``, degree > 40 or the zero polynomial.
    """

def certify_below(
    coeffs: npt.NDArray[np.float64], a: float, b: float, exact: bool = True
) -> tuple[int, float]:
    """Algorithm 1: ``(code, t)``; 0 = ``F < 0`` on ``[a, b]`` proven, 1 = ``F >= 0`` somewhere
    (near ``t``), 2 = unknown (only with ``exact=False``)."""

def certify_below_many(
    coeffs: npt.NDArray[np.float64], a: float, b: float, exact: bool = True
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """:func:`certify_below` on every row of ``coeffs`` (n, C): ``(codes, t, decided_fast)``."""

def certify_spline(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    limits: npt.NDArray[np.float64],
    g: float = 9.81,
    exact: bool = True,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64]]:
    """Bound certificates of a (S, 4, C) spline: ``(codes (5, S), t (5, S))``.

    ``limits`` = ``[thrust_max, thrust_min, thrust_rate_max, tilt_rate_max, body_rate_max]``
    (mass-normalised, ``inf`` = not checked); codes 0 within, 1 violated, 2 unknown (with
    ``exact`` only for a body rate whose roll level is undecided), 3 not checked; ``t`` the
    estimated absolute time of a violation (NaN otherwise).
    """

def bound_polynomial(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    segment: int,
    bound: int,
    limit: float,
    g: float = 9.81,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Rigorous enclosure ``(lo, hi)`` of the checked polynomial of row ``bound`` on ``segment``
    in ``u = (t - knots[i]) / (knots[i+1] - knots[i])`` (the body rate at the 45 deg roll level)."""

# --- workspace certificates (regions.rs) ------------------------------------------------------

def certify_halfspace(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    normal: npt.NDArray[np.float64],
    offset: float,
    touch_order: int = 0,
    exact: bool = True,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], float]:
    """``normal . p(t) > offset`` per segment of a (S, 4, C) spline: ``(codes (S,), t (S,),
    residual)``. With ``touch_order = k >= 1`` the last segment touches the plane at its end: a
    ``k``-fold root at ``t_f`` is divided out, the quotient certified, and ``residual`` bounds how
    far beyond the plane the position can be (m). Codes 0 within, 1 violated, 2 unknown."""

def certify_sphere_outside(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    center: npt.NDArray[np.float64],
    radius: float,
    exact: bool = True,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], float]:
    """``|p(t) - center| > radius`` per segment; as :func:`certify_halfspace`."""

def certify_speed(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    v_max: float,
    exact: bool = True,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], float]:
    """``|v(t)| < v_max`` per segment; as :func:`certify_halfspace`."""
