"""Stubs for the compiled kernels (avp_rust). Coefficients are in ascending powers."""

import numpy as np
import numpy.typing as npt

__all__ = [
    "BOUND_NAMES",
    "KernelError",
    "__version__",
    "anticipate",
    "append_rows",
    "bound_polynomial",
    "certify_below",
    "certify_below_many",
    "certify_halfspace",
    "certify_speed",
    "certify_sphere_outside",
    "certify_spline",
    "eval_spline",
    "fov_gradient",
    "fov_linearise",
    "fov_row_matrices",
    "fov_step_rows",
    "kkt_residuals",
    "max_violation",
    "physical_coefficients",
    "scaled_excess",
    "spline_visibility",
    "sturm_count",
    "trackability_rows",
]

__version__: str

class KernelError(ValueError):
    """A kernel rejected an argument. ``str(exc)`` is ``"{arg}: {detail}"``."""

    arg: str
    """Name of the offending argument (``"coeffs"``, ``"knots"``, ``"limits"``, ``"budget"``...)."""
    detail: str
    """What is wrong with it and what to do."""

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

def physical_coefficients(
    c_hat: npt.NDArray[np.float64], scale: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], bool]:
    """A decision vector ``c_hat`` (axis-major: axes x segments x powers, the QP's layout) as
    spline coefficients ``(segments, axes, powers)`` in powers of ``t - t_i``: ``c[a, i, k] *
    scale[i, k]`` with ``scale (segments, powers)`` (``T_i^-k``), one product per entry; and
    whether they are all finite. Any layout and float dtype. ``KernelError`` naming ``scale`` or
    ``c_hat`` when ``c_hat`` is not whole axes of ``scale.size`` coefficients."""

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

def fov_gradient(
    x: npt.NDArray[np.float64],
    psi: npt.NDArray[np.float64],
    a: npt.NDArray[np.float64],
    s: npt.NDArray[np.float64],
    axis_B: npt.NDArray[np.float64],
    cos_half: float,
    g: float,
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """FoV cone (7) and its gradient at ``m`` points (``x``, ``a``: ``(m, 3)``, ``psi``: ``(m,)``):
    ``(h (m,), d_x (m, 3), d_psi (m,), d_a (m, 3), distance (m,))``; non-finite where the
    construction (13) is singular. Raises ``KernelError`` on bad shapes or non-finite ``s``,
    ``axis_B``, ``cos_half``, ``g``."""

def fov_linearise(
    x0: npt.NDArray[np.float64],
    psi0: npt.NDArray[np.float64],
    a0: npt.NDArray[np.float64],
    s: npt.NDArray[np.float64],
    axis_B: npt.NDArray[np.float64],
    cos_half: float,
    g: float,
    trust: tuple[float, float, float],
    margin: float,
    reach_fraction: float,
    progress_fraction: float,
    policy: str,
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.bool_],
    npt.NDArray[np.bool_],
    bool,
]:
    """The linearised FoV rows (8) at ``m`` points (:func:`avp.qp.fov.fov_blocks`):
    ``(h0, reachable, gx (m, 3), ga (m, 3), gp, rhs, placed, progress, hold)``. ``trust``: the
    box (9) radii in position, acceleration and yaw (``inf`` allowed); ``policy``: ``"keep"``,
    ``"skip"`` or ``"progress"``. A degenerate point has no row, a zero gradient and
    ``h0 = inf``. ``hold``: every placed row holds at the linearisation point. Raises
    ``KernelError`` on bad shapes, a negative radius, margin or fraction, or an unknown policy."""

def fov_row_matrices(
    n_segments: int,
    seg: npt.NDArray[np.int64],
    p0: npt.NDArray[np.float64],
    p2: npt.NDArray[np.float64],
    gx: npt.NDArray[np.float64],
    ga: npt.NDArray[np.float64],
    gp: npt.NDArray[np.float64],
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """Dense FoV rows of ``k`` placed points (:func:`avp.qp.fov.fov_rows`): rows (8) ``(k, n)``
    and the trust-region (9) rows in position ``(3k, n)``, acceleration ``(3k, n)`` and yaw
    ``(k, n)``, ``n = 4 n_segments C``, from each point's segment ``seg``, basis rows ``p0``,
    ``p2`` ``(k, C)`` and gradients ``gx``, ``ga`` ``(k, 3)``, ``gp`` ``(k,)``. Raises
    ``KernelError`` on bad shapes, a segment outside ``0..n_segments`` or rows wider than
    65536 columns."""

def spline_visibility(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    times: npt.NDArray[np.float64],
    rotor_drag: float,
    s: npt.NDArray[np.float64],
    axis_B: npt.NDArray[np.float64],
    cos_half: float,
    g: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Visibility of ``s`` from ``k`` plans (:func:`avp.metrics.visibility_many`, cone (7) only)
    whose stacked coefficients ``coeffs (S, 4k, C)`` (x, y, z, yaw of each plan in turn) on
    ``knots (S + 1,)`` the kernel evaluates at their relative ``times (n,)`` (at least 2), with
    the thrust direction ``a + rotor_drag v``. Returns the trapezoid time fractions, path
    fractions and first times out of view (NaN: never) ``(k,)`` each. Raises ``KernelError`` on
    bad shapes, a negative or non-finite ``rotor_drag``, or non-finite ``s``, ``axis_B``,
    ``cos_half``, ``g``."""

def fov_step_rows(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    tau: npt.NDArray[np.float64],
    rotor_drag: float,
    s: npt.NDArray[np.float64],
    axis_B: npt.NDArray[np.float64],
    cos_half: float,
    g: float,
    trust: tuple[float, float, float],
    margin: float,
    reach_fraction: float,
    progress_fraction: float,
    policy: str,
    n_segments: int,
    seg: npt.NDArray[np.int64],
    p0: npt.NDArray[np.float64],
    p2: npt.NDArray[np.float64],
    build_rows: bool,
) -> tuple[
    tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_], npt.NDArray[np.bool_], bool],
    tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
          npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]],
    tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
          npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
          npt.NDArray[np.float64], npt.NDArray[np.float64]] | None,
]:
    """The FoV rows of one SQP step (:func:`avp.qp.fov.linearise_on_spline`), linearised on the
    reference spline ``coeffs (S, 4, C)``, ``knots (S + 1,)`` at its relative times ``tau (m,)``
    (acceleration ``a + rotor_drag v``): the terms as :func:`fov_linearise` gives them and the
    placed points' rows as :func:`fov_row_matrices` gives them, on the QP's point basis ``seg
    (m,)``, ``p0``, ``p2 (m, C)`` of ``n_segments`` segments. Returns ``((h0, reachable, placed,
    progress, hold), (gx, ga, gp, rhs, x0, a0, psi0), (row8, rx, x_lo, x_hi, ra, a_lo, a_hi, ryaw,
    yaw_lo, yaw_hi))``: per point, then per placed point, then the blocks (trust bounds: the
    point minus and plus its radius), or ``None`` unless ``build_rows``. Raises ``KernelError``
    on bad shapes, no point, a spline without 4 axes, a negative or non-finite ``rotor_drag`` or
    the :func:`fov_linearise` conditions."""

# --- the rows appended to an eliminated QP (reduce.rs) -------------------------------------------

def append_rows(
    g: npt.NDArray[np.float64],
    lower: npt.NDArray[np.float64],
    upper: npt.NDArray[np.float64],
    g_z: npt.NDArray[np.float64],
    lower_z: npt.NDArray[np.float64],
    upper_z: npt.NDArray[np.float64],
    m_rows: npt.NDArray[np.float64] | None,
    blocks: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]],
    z_basis: npt.NDArray[np.float64],
    c_p: npt.NDArray[np.float64],
    r: npt.NDArray[np.float64] | None,
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64] | None,
]:
    """A QP's rows with ``blocks`` (``(matrix, lower, upper)`` triples) appended
    (:meth:`avp.qp.assemble.PerchingQp.with_inequalities`): ``(g, lower, upper)`` in the
    coefficients ``c``, ``(g_z, lower_z, upper_z)`` in ``z`` with ``c = c_p + z_basis z``, and
    ``m_rows = g_z R^-1`` (``r``: the reduced Hessian's upper Cholesky factor) or ``None`` without
    ``r`` or ``m_rows``, or when a new row is not finite. New arrays; the inputs are not changed.
    Raises ``KernelError`` on bad shapes or an empty ``c_p``."""

# --- bound certificates (sturm.rs, exact.rs, certify.rs, bounds.rs) ---------------------------

BOUND_NAMES: list[str]

def sturm_count(coeffs: npt.NDArray[np.float64], a: float, b: float) -> int:
    """Exact number of distinct real roots of ``sum coeffs[k] x^k`` in the closed ``[a, b]``.

    Interval-arithmetic Sturm sequence, exact big-integer fallback when unsure. Raises
    ``KernelError`` (a ``ValueError``) on NaN/inf, ``a > b``, degree > 40 or the zero polynomial.
    """

def certify_below(
    coeffs: npt.NDArray[np.float64],
    a: float,
    b: float,
    exact: bool = True,
    budget: float = ...,
) -> tuple[int, float]:
    """Algorithm 1: ``(code, t)``; 0 = ``F < 0`` on ``[a, b]`` proven, 1 = ``F >= 0`` somewhere
    (near ``t``), 2 = unknown (with ``exact=False``, or when the exact fallback needs more than
    ``budget`` seconds; default ``inf``)."""

def certify_below_many(
    coeffs: npt.NDArray[np.float64],
    a: float,
    b: float,
    exact: bool = True,
    budget: float = ...,
    method: str = "bernstein",
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """:func:`certify_below` on every row of ``coeffs`` (n, C): ``(codes, t, decided_fast)``.

    ``budget`` (seconds, default ``inf``) applies to each row's exact fallback; ``method`` is
    ``"bernstein"`` (exact Bernstein subdivision) or ``"sturm"`` (the previous exact Sturm chain,
    unbudgeted, kept for comparisons)."""

def certify_spline(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    limits: npt.NDArray[np.float64],
    g: float = 9.81,
    exact: bool = True,
    budget: float = ...,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64]]:
    """Bound certificates of a (S, 4, C) spline: ``(codes (5, S), t (5, S))``.

    ``budget`` (seconds, default ``inf``) bounds the exact fallbacks of the whole call; cells
    left undecided when it runs out are 2 (unknown).

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

def trackability_rows(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    snap_max: float,
    ratio_max: float,
    g: float = 9.81,
) -> npt.NDArray[np.float64]:
    """Exact, upward-rounded coefficients of the trackability polynomials of every segment of
    ``coeffs`` ``(S, A >= 3, C)``: the row of ``|s|^2 - snap_max^2`` (if ``snap_max`` is finite),
    then that of ``|s|^2 - ratio_max^2 |a + g e3|^2`` (if ``ratio_max`` is finite), ascending in
    ``u = (t - t_i) / T_i``, zero-padded: ``(S * rows per segment, width)``. Bit for bit the
    ``fractions.Fraction`` computation of :mod:`avp.trackability`; ``KernelError`` when a
    coefficient is outside the normal float range."""

# --- workspace certificates (regions.rs) ------------------------------------------------------

def certify_halfspace(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    normal: npt.NDArray[np.float64],
    offset: float,
    touch_order: int = 0,
    exact: bool = True,
) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.float64], float]:
    """``normal . p(t) > offset`` per segment of a ``(S, A, C)`` spline whose first three axes
    are the position (``A >= 3``; fewer: ``KernelError`` on ``coeffs``): ``(codes (S,), t (S,),
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

# --- the time search's scaling law (time_scaling.rs) ------------------------------------------

def scaled_excess(
    coeffs: npt.NDArray[np.float64],
    knots: npt.NDArray[np.float64],
    per_segment: int,
    s2: npt.NDArray[np.float64],
    g: float,
    *,
    accel_max: float,
    accel_min: float,
    mass: float,
    thrust_rate_max: float,
    tilt_rate_max: float,
    body_rate_max: float,
) -> npt.NDArray[np.float64]:
    """Worst relative excess ``max(value / limit) - 1`` over the thrust range (15), thrust rate
    (21), tilt rate (22) and body rate (24) of the spline (``(segments, 4, coeffs)``: x, y, z,
    yaw) time-scaled by each ``s`` with ``s2 = s^-2``, on ``per_segment`` midpoint samples per
    segment; shape ``(len(s2),)``, NaN where a sample's arithmetic gives NaN (as NumPy's). The
    rate limits may be ``inf`` (not checked), ``accel_min`` ``0``. Raises ``KernelError``
    naming the argument on bad shapes, non-finite or non-positive ``s2``, a non-finite ``g``,
    ``per_segment`` outside ``[1, 100000]`` (``OverflowError`` beyond 64 bits) or a meaningless limit (``accel_max``,
    ``accel_min``, ``mass``, ``thrust_rate_max``, ``tilt_rate_max``, ``body_rate_max``)."""

# --- a QP solution's acceptance checks (qp_check.rs) ------------------------------------------

def max_violation(
    c: npt.NDArray[np.float64],
    a: npt.NDArray[np.float64],
    b: npt.NDArray[np.float64],
    g: npt.NDArray[np.float64],
    lower: npt.NDArray[np.float64],
    upper: npt.NDArray[np.float64],
) -> float:
    """Largest relative violation at ``c`` of ``a c = b`` and ``lower <= g c <= upper``: the
    maximum of 0, ``|a_i c - b_i| / max(1, |b_i|)`` and ``(g_i c - upper_i) / max(1,
    |upper_i|)``, ``(lower_i - g_i c) / max(1, |lower_i|)`` (an infinite bound scales by 1); NaN
    when a residual is NaN. ``a`` is ``(len(b), len(c))`` and ``g`` ``(len(lower),
    len(c))``, of any layout and float dtype (read by their values); ``KernelError`` naming the
    argument on a wrong shape."""

def kkt_residuals(
    h: npt.NDArray[np.float64],
    q: npt.NDArray[np.float64],
    g: npt.NDArray[np.float64],
    x: npt.NDArray[np.float64],
    lam: npt.NDArray[np.float64],
    lower: npt.NDArray[np.float64],
    upper: npt.NDArray[np.float64],
) -> tuple[float, float]:
    """``(dual residual, duality gap)`` of ``min 1/2 x^T h x + q^T x`` s.t. ``lower <= g x <=
    upper`` at ``x`` with signed multipliers ``lam`` (``> 0``: upper bound active): ``max |h x +
    q + g^T lam|`` (0 for an empty ``x``) and ``|x^T h x + q^T x + sum_{lam > 0} upper lam +
    sum_{lam < 0} lower lam|``; NaN propagates, except from a row of ``g`` whose multiplier is
    zero (not read). Arrays of any layout and float dtype are read by their values;
    ``KernelError`` naming the argument on a wrong shape."""
