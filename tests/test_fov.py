"""FoV constraint (7), its linearisation (8) with trust region (9), the SQP policy and the
fallback (16)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
import pytest
import qpsolvers
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import avp
from avp import (
    Camera,
    FovConfig,
    FovPointPolicy,
    PerchTarget,
    PlannerConfig,
    State,
    plan_detailed,
    visibility,
)
from avp.errors import ConfigError
from avp.frames import GRAVITY, attitude
from avp.qp.assemble import build_perching_qp
from avp.qp.fov import (
    FOV_PREFIX,
    FovGradient,
    fov_blocks,
    fov_gradient,
    fov_h,
    fov_times,
)
from avp.qp.layout import YAW, DecisionLayout
from avp.qp.rows import point_rows

Array = npt.NDArray[np.float64]
CAM = Camera()
floats = st.floats(allow_nan=False, allow_infinity=False)


def _vec(lo: float, hi: float):
    return st.tuples(*(st.floats(lo, hi) for _ in range(3))).map(np.array)


def _direction():
    return _vec(-1.0, 1.0).filter(lambda u: np.linalg.norm(u) > 0.1).map(lambda u: u / np.linalg.norm(u))


# Accelerations with thrust |a + g e3| >= 4.8 m/s^2 (a_z >= -5) and a tilt below ~60 deg, where the
# construction (13) is regular.
ACC = st.tuples(st.floats(-8, 8), st.floats(-8, 8), st.floats(-5, 5)).map(np.array)
MOUNTS = st.sampled_from([
    avp.camera.FRONT_CAMERA_R_BC,
    np.eye(3),  # looking along b3
    np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) @ avp.camera.FRONT_CAMERA_R_BC,
])


def test_camera_defaults_and_validation() -> None:
    R = np.eye(3)
    assert np.allclose(CAM.axis(R), [1.0, 0.0, 0.0])  # front camera looks along b1
    assert CAM.half_fov == pytest.approx(math.radians(35.0))
    with pytest.raises(ConfigError, match="camera.half_fov"):
        Camera(half_fov=2.0)
    with pytest.raises(ConfigError, match="camera.R_BC"):
        Camera(R_BC=2 * np.eye(3))
    with pytest.raises(ConfigError, match="fov.n_points"):
        FovConfig(n_points=0)
    with pytest.raises(ConfigError, match="fov.gate"):
        FovConfig(gate=-0.1)
    with pytest.raises(ConfigError, match="fov.point_policy"):
        FovConfig(point_policy="skip")  # type: ignore[arg-type]
    assert PlannerConfig().fov == FovConfig()


@settings(max_examples=60, deadline=None)
@given(x=_vec(-3, 3), d=_direction(), dist=st.floats(0.5, 10), psi=st.floats(-math.pi, math.pi), a=ACC, R_BC=MOUNTS)
def test_gradient_matches_finite_differences(x, d, dist, psi, a, R_BC) -> None:
    cam = Camera(R_BC=R_BC)
    s = x + dist * d
    g = fov_gradient(x, psi, a, s, cam)
    eps = 1e-6

    def h(xx, pp, aa):
        return float(fov_h(xx, pp, aa, s, cam)[0])

    num_x = [(h(x + eps * e, psi, a) - h(x - eps * e, psi, a)) / (2 * eps) for e in np.eye(3)]
    num_a = [(h(x, psi, a + eps * e) - h(x, psi, a - eps * e)) / (2 * eps) for e in np.eye(3)]
    num_p = (h(x, psi + eps, a) - h(x, psi - eps, a)) / (2 * eps)
    scale = max(1.0, dist)
    np.testing.assert_allclose(g.d_x[0], num_x, atol=1e-6 * scale)
    np.testing.assert_allclose(g.d_a[0], num_a, atol=1e-6 * scale)
    assert g.d_psi[0] == pytest.approx(num_p, abs=1e-6 * scale)


@settings(max_examples=40, deadline=None)
@given(x=_vec(-3, 3), d=_direction(), dist=st.floats(0.5, 10), psi=st.floats(-math.pi, math.pi), a=ACC)
def test_h_matches_cone_geometry(x, d, dist, psi, a) -> None:
    """h/|n_d| = cos(half_fov) - cos(angle between n_d and the optical axis)."""
    s = x + dist * d
    e_c = CAM.axis(attitude(a, psi))
    ang = math.acos(np.clip(d @ e_c, -1, 1))
    assert fov_h(x, psi, a, s, CAM)[0] / dist == pytest.approx(math.cos(CAM.half_fov) - math.cos(ang), abs=1e-12)
    assert bool(fov_h(x, psi, a, s, CAM)[0] <= 0) == bool(CAM.sees(x, attitude(a, psi), s)) or abs(ang - CAM.half_fov) < 1e-9


@settings(max_examples=120, deadline=None)
@given(x=_vec(-3, 3), d=_direction(), dist=st.floats(0.5, 10), psi=st.floats(-math.pi, math.pi), a=ACC,
       half=st.floats(10.0, 80.0), margin=st.floats(0.0, 0.4), R_BC=MOUNTS)
def test_narrowed_camera_sees_where_the_rows_with_margin_hold(x, d, dist, psi, a, half, margin, R_BC) -> None:
    """``Camera.narrowed(margin)`` (numpy geometry of ``sees``) contains a point exactly where the
    FoV kernel's ``h/|n_d| <= -margin``, the row (8) with ``fov.margin`` at its linearisation point."""
    cam = Camera(R_BC=R_BC, half_fov=math.radians(half))
    s = x + dist * d
    h = float(fov_h(x, psi, a, s, cam)[0]) / dist
    narrow = cam.narrowed(margin)
    if narrow is None:  # the rows ask for cos(angle) >= cos(half_fov) + margin >= 1
        assert math.cos(cam.half_fov) + margin >= 1.0
        assert h > -margin or abs(h + margin) < 1e-12
        return
    assert narrow.half_fov <= cam.half_fov and (margin > 0 or narrow is cam)
    assume(abs(h + margin) > 1e-9)
    assert bool(narrow.sees(x, attitude(a, psi), s)) == bool(h <= -margin)


def test_narrowed_camera_validation() -> None:
    with pytest.raises(ConfigError, match="fov.margin"):
        CAM.narrowed(-0.01)
    with pytest.raises(ConfigError, match="fov.margin"):
        CAM.narrowed(float("nan"))
    fov = FovConfig()
    assert fov.score_camera is fov.camera
    assert FovConfig(margin=0.5).score_camera is None  # cos 35 deg + 0.5 > 1: no direction
    narrow10 = Camera(half_fov=math.radians(10.0))
    assert narrow10.narrowed(1e-300) is narrow10  # below the float spacing of cos: never a wider cone
    with pytest.raises(ConfigError, match="fov.margin"):
        CAM.narrowed(True)  # type: ignore[arg-type]


def test_fov_margin_is_scored_in_its_narrowed_cone() -> None:
    """A first plan's SQP keeps steps that bring the pad inside the cone the margin asks for. On a
    drag-aware wall perch the plan without margin has the pad about 33 deg off the axis in the fast
    part; with ``margin = 0.04`` (about 31 deg) and a trust box that lets the attitude move, the
    SQP's steps raise the time in the narrowed cone. Scored in the plain cone, as before, step 1
    was rejected and the plan was the margin-free one."""
    target = PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90))
    start = State.hover([0.0, 0.0, 1.5])
    base = PlannerConfig(alpha_nominal=6.0, workspace=avp.Workspace(ground_z=0.3))
    base = dataclasses.replace(base, limits=dataclasses.replace(base.limits, rotor_drag=0.35))
    narrow = FovConfig(margin=0.04).score_camera
    assert narrow is not None and math.degrees(narrow.half_fov) == pytest.approx(30.78, abs=0.01)
    in_narrow = []
    for margin in (0.0, 0.04):
        cfg = dataclasses.replace(base, fov=dataclasses.replace(base.fov, margin=margin, trust_acceleration=0.6))
        result = plan_detailed(start, target, cfg)
        assert result.status is avp.PlanStatus.SOLVED
        in_narrow.append(visibility(result.trajectory, target, narrow, rotor_drag=0.35).time_fraction)
        if margin:
            assert any("SQP step 2: visibility" in line for line in result.log)
    assert in_narrow[1] > in_narrow[0] + 0.1


@settings(max_examples=40, deadline=None)
@given(incline=st.sampled_from([0.0, 30.0, 60.0, 90.0, 120.0]), distance=st.floats(2.0, 6.0),
       drag=st.sampled_from([0.0, 0.3]), shift=st.floats(-0.5, 0.5), margin=st.sampled_from([0.0, 0.04]))
def test_the_sqp_score_is_the_visibility_fractions_summed(incline, distance, drag, shift, margin) -> None:
    """The SQP's score of plans on one QP's knots (the kernel's fractions, summed in one pass)
    is ``time_fraction + path_fraction`` of :func:`avp.metrics.visibility_many`'s checked path,
    bit for bit, for one plan and for two; plans on knots of their own are scored one by one."""
    from avp import perception
    from avp.metrics import _visibility_checked
    from avp.timing import initial_durations

    target = PerchTarget.from_incline([distance, shift, 1.5], math.radians(incline))
    start = State.hover([0.0, 0.0, 1.5])
    cfg = PlannerConfig()
    cfg = dataclasses.replace(cfg, fov=dataclasses.replace(cfg.fov, margin=margin),
                              limits=dataclasses.replace(cfg.limits, rotor_drag=drag))
    T = initial_durations(start, target, cfg)
    qp = build_perching_qp(start, target, cfg, T)
    A, b = qp.stacked_equalities()
    c = qpsolvers.solve_qp(qp.P.copy(), np.zeros(qp.layout.n_variables), A=A.copy(), b=b.copy(), solver="daqp")
    assume(c is not None)
    one, other = qp.trajectory(c, cfg.g), qp.trajectory(c * (1.0 + 1e-3 * np.cos(np.arange(c.size))), cfg.g)
    camera = cfg.fov.score_camera
    assert camera is not None

    def checked(trajs):
        step = trajs[0].duration / perception._SCORE_GRID
        return [v.time_fraction + v.path_fraction
                for v in _visibility_checked(trajs, target, camera, step, cfg.limits.rotor_drag)]

    paths = {"fast": 0, "checked": 0}

    def counted(name, fn):
        def call(*args, **kwargs):
            paths[name] += 1
            return fn(*args, **kwargs)
        return call

    fast, slow = perception._cone_fractions, perception._visibility_checked
    for trajs in ((one,), (one, other), (other, one)):
        expected = checked(trajs)
        perception._cone_fractions, perception._visibility_checked = counted("fast", fast), counted("checked", slow)
        try:
            assert perception._scores(trajs, target, cfg) == expected
        finally:
            perception._cone_fractions, perception._visibility_checked = fast, slow
    assert paths == {"fast": 3, "checked": 0}  # one QP's plans: the kernel's fractions, summed
    alone = avp.Trajectory.from_relative_knots(other.coefficients, other.knots_rel.copy(), other.t0, other.g)
    assert alone.knots_rel is not one.knots_rel
    expected = checked((one, alone))
    perception._visibility_checked = counted("checked", slow)
    try:
        assert perception._scores((one, alone), target, cfg) == expected
    finally:
        perception._visibility_checked = slow
    assert paths == {"fast": 3, "checked": 1}  # knots of their own: the checked path


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), t0=st.one_of(st.just(0.0), st.floats(0.0, 50.0), st.floats(1.0e9, 2.0e9)),
       lag=st.floats(0.0, 0.5), stretch=st.floats(0.7, 1.3), build=st.booleans())
def test_linearise_on_maps_times_as_the_array_formula(seed, t0, lag, stretch, build) -> None:
    """``perception.linearise_on`` (the reference times in Python floats) linearises at the
    reference's relative times of the array formula ``clip(t0 + t (tf_ref - max(t0, t0_ref)) /
    tf, t0_ref, tf_ref)``, then ``Trajectory._relative``: the same linearisation, bit for bit, as
    :func:`linearise_on_spline` given those times, for a replan's QP starting ``lag`` after its
    reference, at any clock value, with the plans ending together or not."""
    from avp.perception import linearise_on
    from avp.qp.fov import linearise_on_spline
    from avp.timing import initial_durations

    rng = np.random.default_rng(seed)
    target = PerchTarget.from_incline([rng.uniform(2.5, 5.0), rng.uniform(-1, 1), 1.5], math.radians(60))
    start = State.hover([0.0, 0.0, 1.5])
    cfg = PlannerConfig()
    T = initial_durations(start, target, cfg)
    ref_knots = np.concatenate([[0.0], np.cumsum(T * stretch)])
    coeffs = rng.normal(0.0, 1.0, (T.size, 4, cfg.degree + 1))
    reference = avp.Trajectory.from_relative_knots(coeffs, ref_knots, t0)
    state = dataclasses.replace(start, time=t0 + lag)
    qp = build_perching_qp(state, target, cfg, T)
    tf = float(qp.knots_rel[-1])
    times = fov_times(0.0, tf, cfg.fov)
    start_t = max(qp.t0, reference.t0)
    t_ref = np.clip(qp.t0 + times * (reference.tf - start_t) / tf, reference.t0, reference.tf)
    tau = reference._relative(t_ref)
    want = linearise_on_spline(qp.layout, qp.knots_rel, times, reference.coefficients, reference.knots_rel, tau,
                               target.point, cfg.fov, cfg.g, rotor_drag=cfg.limits.rotor_drag, build_blocks=build)
    got = linearise_on(qp, reference, target, cfg, build_blocks=build)
    for name in ("times", "h0", "reachable", "placed", "progress"):
        assert getattr(got, name).tobytes() == getattr(want, name).tobytes(), name
    assert got.rows is not None and want.rows is not None
    for name in ("x0", "a0", "psi0", "rhs"):
        assert getattr(got.rows, name).tobytes() == getattr(want.rows, name).tobytes(), name


LINEARISATION_BOUND = 0.03
"""Largest |h - h_lin| / |n_d0| inside the box trust region (9) for |n_d0| >= 1 m and thrust
>= 4.8 m/s^2 (tilt < ~60 deg): about 1.7 deg of cone angle near the 35 deg edge (Fig. 6).
Sampling 20,000 random points gave 0.021."""


@settings(max_examples=80, deadline=None)
@given(
    x=_vec(-3, 3), d=_direction(), dist=st.floats(1.0, 10), psi=st.floats(-math.pi, math.pi), a=ACC,
    dx=_vec(-0.05, 0.05), da=_vec(-0.2, 0.2), dp=st.floats(-0.1, 0.1),
)
def test_linearisation_error_inside_trust_region(x, d, dist, psi, a, dx, da, dp) -> None:
    s = x + dist * d
    g = fov_gradient(x, psi, a, s, CAM)
    exact = fov_h(x + dx, psi + dp, a + da, s, CAM)[0]
    lin = g.h[0] + g.d_x[0] @ dx + g.d_a[0] @ da + g.d_psi[0] * dp
    assert abs(exact - lin) / dist <= LINEARISATION_BOUND


def _scenario(distance: float, incline_deg: float = 90.0) -> tuple[State, PerchTarget]:
    """Hover at the pad height, facing a pad ``distance`` ahead."""
    return State.hover([0.0, 0.0, 1.0]), PerchTarget.from_incline([distance, 0.0, 1.0], math.radians(incline_deg))


def _score(traj, target) -> tuple[float, float]:
    v = visibility(traj, target, dt=1e-3)
    return v.time_fraction, v.path_fraction


def _terminal_ok(traj, target) -> None:
    assert np.linalg.norm(traj(traj.tf) - target.point) < 1e-3
    b3 = traj.attitude(traj.tf)[:, 2]
    assert math.degrees(math.acos(np.clip(b3 @ target.s3, -1, 1))) < 0.5


def test_fov_blocks_are_named_and_removable() -> None:
    state, target = _scenario(3.5)
    cfg = PlannerConfig(fov=FovConfig(point_policy=FovPointPolicy.KEEP))
    off = plan_detailed(state, target, dataclasses.replace(cfg, fov=FovConfig(enabled=False)))
    T = off.durations
    qp = build_perching_qp(state, target, cfg, T)
    times = fov_times(0.0, float(T.sum()), cfg.fov)
    assert times.size == cfg.fov.n_points and times[-1] == pytest.approx(T.sum() - cfg.fov.gate)
    d = off.trajectory.derivatives(state.time + times, (0, 2))
    lin = fov_blocks(qp.layout, qp.knots_rel, times, d[0, :, :3], d[0, :, 3], d[1, :, :3], target.point, cfg.fov)
    with_rows = qp.with_inequalities(*lin.blocks)
    assert all(b.name.startswith("fov") for b in lin.blocks) and lin.n_rows > 0
    assert len(with_rows.without("fov").inequalities) == len(qp.inequalities)
    # The linearised rows at the linearisation point equal h/|n_d| there (exactness at z0).
    c_off = off.qp.c_hat
    rows = lin.blocks[0]
    np.testing.assert_allclose(rows.matrix @ c_off - rows.upper, lin.h0[lin.placed], atol=1e-9)


SCENARIOS = [(1.5, 90.0), (3.5, 90.0), (7.5, 90.0), (3.5, 60.0)]


@pytest.mark.parametrize(("distance", "incline"), SCENARIOS)
def test_visibility_with_fov_not_below_without(distance: float, incline: float) -> None:
    state, target = _scenario(distance, incline)
    off = plan_detailed(state, target, PlannerConfig(fov=FovConfig(enabled=False)))
    on = plan_detailed(state, target, PlannerConfig())
    assert on.ok and off.ok
    t_off, p_off = _score(off.trajectory, target)
    t_on, p_on = _score(on.trajectory, target)
    assert t_on + p_on >= t_off + p_off - 1e-9
    _terminal_ok(on.trajectory, target)


@pytest.mark.parametrize("squeeze", [1.0, 0.6])
@pytest.mark.parametrize(("distance", "incline"), SCENARIOS)
def test_a_replan_to_a_moved_estimate_keeps_its_fov_rows_and_perches(distance: float, incline: float, squeeze: float) -> None:
    """A replan 1/30 s in, to an estimate 8 cm deeper: the FoV rows are linearised on the replan's
    own FoV-free solution (so the trust region (9) is centred on a point that meets the perching
    rows) and kept, in one SQP step; with durations squeezed to 0.6 the time search runs and the
    FoV stage starts from its certified step. The plan perches exactly and meets the limits."""
    state, target = _scenario(distance, incline)
    prev = plan_detailed(state, target, PlannerConfig()).trajectory
    t = prev.t0 + 1 / 30
    D = prev.derivatives(t, (0, 1, 2, 3))
    s = State(position=D[0, :3], velocity=D[1, :3], acceleration=D[2, :3], jerk=D[3, :3],
              yaw=D[0, 3], yaw_rate=D[1, 3], time=t)
    moved = PerchTarget(point=target.point - 0.08 * target.s3, R_WS=target.R_WS)
    cfg = PlannerConfig()
    again = plan_detailed(s, moved, cfg, durations=np.full(3, squeeze * (prev.tf - t) / 3), previous=prev)
    assert again.ok and again.status is avp.PlanStatus.SOLVED and not again.fov_dropped
    assert any(line.startswith("QP + FoV (linearised on that solution)") for line in again.log)
    assert not any(line.startswith("SQP step") for line in again.log)  # a replan takes one step
    if squeeze < 1.0:
        assert any("the search step's solution" in line for line in again.log)
        assert any(line in ("FoV rows added back: bounds certified", "FoV rows hold at the certified plan: bounds certified")
                   for line in again.log)
    _terminal_ok(again.trajectory, moved)
    tr = again.trajectory
    ts = tr.sample(1e-3)
    f = tr.thrust(ts)
    lim = cfg.limits
    assert f.min() >= lim.accel_min - 1e-9 and f.max() <= lim.accel_max + 1e-9
    assert np.linalg.norm(tr.body_rates(ts)[:, :2], axis=1).max() <= lim.tilt_rate_max + 1e-9


SOLVERS = ["daqp", "osqp", "proxqp"]


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("with_previous", [False, True])
def test_incompatible_fov_falls_back(solver: str, with_previous: bool) -> None:
    """Rows kept where the cone cannot be reached inside the trust region (KEEP) are
    incompatible with the perch on a 90 deg wall: the fallback (16) must fire and still perch."""
    if solver not in qpsolvers.available_solvers:
        pytest.skip(f"{solver} not installed")
    state, target = _scenario(3.5)
    cfg = PlannerConfig(solver=solver, fov=FovConfig(point_policy=FovPointPolicy.KEEP, gate=0.0))
    previous = None
    if with_previous:
        previous = plan_detailed(state, target, dataclasses.replace(cfg, fov=FovConfig(enabled=False))).trajectory
    result = plan_detailed(state, target, cfg, previous=previous)
    assert result.status is avp.PlanStatus.SOLVED_WITHOUT_FOV
    assert result.fov_dropped
    assert any("incompatible (16)" in line for line in result.log)
    _terminal_ok(result.trajectory, target)


@pytest.mark.parametrize("solver", ["osqp", "proxqp"])
def test_iterative_solvers_plan_with_fov(solver: str) -> None:
    if solver not in qpsolvers.available_solvers:
        pytest.skip(f"{solver} not installed")
    state, target = _scenario(3.5)
    result = plan_detailed(state, target, PlannerConfig(solver=solver))
    assert result.ok
    _terminal_ok(result.trajectory, target)


def test_disabled_fov_is_plain_qp() -> None:
    state, target = _scenario(1.5)
    result = plan_detailed(state, target, PlannerConfig(fov=FovConfig(enabled=False)))
    assert result.ok and not result.fov_dropped
    assert not any("FoV" in line for line in result.log)


# ---------------------------------------------------------------- previous NumPy implementation
# Kept as the reference the Rust kernel and the shared-basis rows must reproduce (to 1e-12).

E3 = np.array([0.0, 0.0, 1.0])


def _ref_skew(w: Array) -> Array:
    """``hat(w)`` for ``w`` of shape ``(..., 3)`` -> ``(..., 3, 3)`` with ``hat(w) u = w x u``."""
    z = np.zeros(w.shape[:-1])
    return np.stack([
        np.stack([z, -w[..., 2], w[..., 1]], -1),
        np.stack([w[..., 2], z, -w[..., 0]], -1),
        np.stack([-w[..., 1], w[..., 0], z], -1),
    ], -2)


def _ref_axis_and_jacobians(psi: Array, a: Array, axis_B: Array, g: float) -> tuple[Array, Array, Array]:
    """``e_c``, ``d e_c / d psi`` (m, 3) and ``d e_c / d a`` (m, 3, 3) for the construction (13)."""
    f = a + g * E3
    fn = np.linalg.norm(f, axis=-1, keepdims=True)
    b3 = f / fn
    eye = np.eye(3)
    J_b3 = (eye - b3[..., :, None] * b3[..., None, :]) / fn[..., None]  # d b3 / d a
    b2d = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], -1)
    b2d_psi = np.stack([-np.cos(psi), -np.sin(psi), np.zeros_like(psi)], -1)
    v = np.cross(b2d, b3)
    vn = np.linalg.norm(v, axis=-1, keepdims=True)
    b1 = v / vn
    b2 = np.cross(b3, b1)
    P1 = (eye - b1[..., :, None] * b1[..., None, :]) / vn[..., None]  # d b1 / d v
    dv_a = _ref_skew(b2d) @ J_b3
    dv_psi = np.cross(b2d_psi, b3)
    J_b1_a = P1 @ dv_a
    J_b1_psi = np.einsum("mij,mj->mi", P1, dv_psi)
    # b2 = b3 x b1: d b2 = hat(b3) d b1 - hat(b1) d b3
    J_b2_a = _ref_skew(b3) @ J_b1_a - _ref_skew(b1) @ J_b3
    J_b2_psi = np.cross(b3, J_b1_psi)
    d1, d2, d3 = axis_B
    e_c = d1 * b1 + d2 * b2 + d3 * b3
    de_psi = d1 * J_b1_psi + d2 * J_b2_psi
    de_a = d1 * J_b1_a + d2 * J_b2_a + d3 * J_b3
    return e_c, de_psi, de_a


def _ref_fov_gradient(
    x: npt.ArrayLike, psi: npt.ArrayLike, a: npt.ArrayLike, s: npt.ArrayLike,
    camera: Camera, g: float = GRAVITY,
) -> FovGradient:
    """The previous NumPy implementation of ``fov_gradient``."""
    xx = np.atleast_2d(np.asarray(x, dtype=float))
    aa = np.atleast_2d(np.asarray(a, dtype=float))
    pp = np.atleast_1d(np.asarray(psi, dtype=float))
    n_d = np.asarray(s, dtype=float) - xx
    dist = np.linalg.norm(n_d, axis=-1)
    e_c, de_psi, de_a = _ref_axis_and_jacobians(pp, aa, camera.axis_B, g)
    c = math.cos(camera.half_fov)
    h = c * dist - np.sum(n_d * e_c, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = n_d / dist[:, None]
    d_x = e_c - c * unit
    d_psi = -np.sum(n_d * de_psi, axis=-1)
    d_a = -np.einsum("mi,mij->mj", n_d, de_a)
    return FovGradient(h=h, d_x=d_x, d_psi=d_psi, d_a=d_a, distance=dist)


def _ref_rows(layout: DecisionLayout, knots: Array, times: Array, gx: Array, ga: Array, gp: Array):
    """The previous construction of the rows: three ``point_rows`` calls and einsum products."""
    Rx = point_rows(layout, knots, 0, times, (0, 1, 2))  # (m, 3, n)
    Ra = point_rows(layout, knots, 2, times, (0, 1, 2))
    Rpsi = point_rows(layout, knots, 0, times, (YAW,))[:, 0, :]  # (m, n)
    G = np.einsum("mi,min->mn", gx, Rx) + np.einsum("mi,min->mn", ga, Ra) + gp[:, None] * Rpsi
    return G, Rx, Ra, Rpsi


def _random_fov_case(rng: np.random.Generator, m: int):
    x = rng.normal(0.0, 2.0, (m, 3))
    a = rng.normal(0.0, 3.0, (m, 3))
    psi = rng.uniform(-math.pi, math.pi, m)
    s = rng.normal(0.0, 2.0, 3)
    x[0] = s  # a degenerate point (|n_d| = 0): both implementations give the same non-finite
    return x, psi, a, s


@pytest.mark.parametrize("mount", range(3))
def test_rust_gradient_equals_previous_numpy_implementation(mount: int) -> None:
    R_BC = [avp.camera.FRONT_CAMERA_R_BC, np.eye(3),
            np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) @ avp.camera.FRONT_CAMERA_R_BC][mount]
    cam = Camera(R_BC=R_BC, half_fov=math.radians(30 + 10 * mount))
    rng = np.random.default_rng(mount)
    for _ in range(20):
        x, psi, a, s = _random_fov_case(rng, 9)
        new, old = fov_gradient(x, psi, a, s, cam), _ref_fov_gradient(x, psi, a, s, cam)
        for name in ("h", "d_x", "d_psi", "d_a", "distance"):
            u, v = getattr(new, name), getattr(old, name)
            assert np.array_equal(np.isfinite(u), np.isfinite(v)), name
            fin = np.isfinite(v)
            np.testing.assert_allclose(u[fin], v[fin], rtol=1e-12, atol=1e-12, err_msg=name)
    # broadcasting: one position against many accelerations, as before
    x, psi, a, s = _random_fov_case(rng, 4)
    np.testing.assert_allclose(fov_gradient(x[1], psi, a, s, cam).d_a, _ref_fov_gradient(x[1], psi, a, s, cam).d_a,
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("policy", list(FovPointPolicy))
def test_fov_blocks_equal_previous_implementation(policy: FovPointPolicy) -> None:
    """Rows (8) and trust-region rows (9) from one shared basis evaluation equal the previous
    construction (point_rows + einsum on the NumPy gradient) to 1e-12."""
    rng = np.random.default_rng(len(policy.name))
    for trial in range(10):
        n_seg, degree = int(rng.integers(1, 5)), int(rng.choice([5, 7, 9]))
        layout = avp.qp.layout.layout_for(n_seg, degree)
        knots = np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 2.0, n_seg))])
        times = np.sort(rng.uniform(0.0, knots[-1], 8))
        x, psi, a, s = _random_fov_case(rng, 8)
        x[0] += 0.5  # keep every point regular here (the degenerate one is tested above)
        fov = FovConfig(point_policy=policy, trust_yaw=math.inf if trial % 3 == 0 else 0.1,
                        margin=0.01 * (trial % 2))
        new = fov_blocks(layout, knots, times, x, psi, a, s, fov)
        grad = _ref_fov_gradient(x, psi, a, s, fov.camera)
        dist = grad.distance
        gx, ga, gp = grad.d_x / dist[:, None], grad.d_a / dist[:, None], grad.d_psi / dist
        G, Rx, Ra, Rpsi = _ref_rows(layout, knots, times, gx, ga, gp)
        h0 = grad.h / dist
        np.testing.assert_allclose(new.h0, h0, rtol=1e-12, atol=1e-12)
        sel = new.placed
        blocks = {b.name: b for b in new.blocks}
        assert (FOV_PREFIX + " rows (8)" in blocks) == bool(sel.any())
        if not sel.any():
            continue
        rows = blocks[FOV_PREFIX + " rows (8)"]
        np.testing.assert_allclose(rows.matrix, G[sel], rtol=1e-12, atol=1e-12)
        lin0 = np.sum(gx * x, 1) + np.sum(ga * a, 1) + gp * psi
        keep = sel & ~new.progress
        np.testing.assert_allclose(rows.upper[keep[sel]], (lin0 - h0 - fov.margin)[keep], rtol=1e-12, atol=1e-12)
        for label, R in (("x", Rx[sel].reshape(-1, layout.n_variables)),
                         ("a", Ra[sel].reshape(-1, layout.n_variables)), ("yaw", Rpsi[sel])):
            name = f"{FOV_PREFIX} trust region (9) {label}"
            if name in blocks:
                np.testing.assert_array_equal(blocks[name].matrix, R)


def _ref_fov_terms(x0: Array, psi0: Array, a0: Array, s: Array, fov: FovConfig) -> dict[str, object]:
    """The former NumPy construction of the row terms of fov_blocks (before the Rust kernel),
    on the same gradient: the kernel must give the same bits."""
    grad = fov_gradient(x0, psi0, a0, s, fov.camera)
    ok = np.isfinite(grad.h) & np.all(np.isfinite(grad.d_a), axis=1) & np.isfinite(grad.d_psi) & (grad.distance > 1e-6)
    dist = np.where(ok, grad.distance, 1.0)
    gx = np.where(ok[:, None], grad.d_x, 0.0) / dist[:, None]
    ga = np.where(ok[:, None], grad.d_a, 0.0) / dist[:, None]
    gp = np.where(ok, grad.d_psi, 0.0) / dist
    h0 = np.where(ok, grad.h, np.inf) / dist

    def times_radius(v: Array, r: float) -> Array:
        return v * r if math.isfinite(r) else np.where(v > 0.0, np.inf, 0.0)

    decrease = (times_radius(np.abs(gx).sum(1), fov.trust_position)
                + times_radius(np.abs(ga).sum(1), fov.trust_acceleration) + times_radius(np.abs(gp), fov.trust_yaw))
    lin0 = np.sum(gx * x0, 1) + np.sum(ga * a0, 1) + gp * psi0
    rhs = lin0 - h0 - fov.margin
    placed, progress = ok.copy(), np.zeros(ok.size, bool)
    hopeless = ok & (h0 - fov.reach_fraction * decrease > -fov.margin)
    if fov.point_policy is FovPointPolicy.SKIP:
        placed &= ~hopeless
    elif fov.point_policy is FovPointPolicy.PROGRESS:
        rhs = np.where(hopeless, lin0 - fov.progress_fraction * decrease, rhs)
        progress = hopeless.copy()
    hold = bool(not np.any(progress & placed)
                and np.all(h0[placed] + fov.margin <= 1e-9 * (1.0 + np.abs(rhs[placed]))))
    return dict(h0=h0, reachable=h0 - decrease, placed=placed, progress=progress, hold=hold,
                gx=gx[placed], ga=ga[placed], gp=gp[placed], rhs=rhs[placed])


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), policy=st.sampled_from(list(FovPointPolicy)),
       radii=st.tuples(*(st.sampled_from([1e-3, 0.05, 0.2, 1.0, math.inf]) for _ in range(3))),
       margin=st.sampled_from([0.0, 0.01, 0.1]), reach=st.sampled_from([0.5, 0.9, 1.0]),
       degenerate=st.booleans())
def test_fov_kernel_row_terms_equal_the_former_numpy_construction_bit_for_bit(
    seed: int, policy: FovPointPolicy, radii: tuple[float, float, float], margin: float, reach: float,
    degenerate: bool,
) -> None:
    rng = np.random.default_rng(seed)
    x, psi, a, s = _random_fov_case(rng, 8)
    if not degenerate:
        x[0] += 0.5
    if degenerate and seed % 3 == 0:
        a[1] = [0.0, 0.0, -GRAVITY]  # no thrust: no usable gradient at that point
    fov = FovConfig(point_policy=policy, trust_position=radii[0], trust_acceleration=radii[1], trust_yaw=radii[2],
                    margin=margin, reach_fraction=reach, camera=Camera(half_fov=math.radians(rng.uniform(20, 60))))
    layout = avp.qp.layout.layout_for(3, 7)
    knots = np.array([0.0, 0.7, 1.4, 2.1])
    times = np.sort(rng.uniform(0.0, 2.1, 8))
    lin = fov_blocks(layout, knots, times, x, psi, a, s, fov)
    ref = _ref_fov_terms(x, psi, a, s, fov)
    for name in ("h0", "reachable", "placed", "progress"):
        np.testing.assert_array_equal(getattr(lin, name), ref[name], err_msg=name)
    assert lin.hold_at_linearisation == ref["hold"]
    rows = lin.rows
    assert rows is not None
    for name in ("gx", "ga", "gp", "rhs"):
        np.testing.assert_array_equal(getattr(rows, name), ref[name], err_msg=name)
    np.testing.assert_array_equal(rows.times, times[ref["placed"]])


def test_fov_blocks_read_column_major_inputs_as_their_values() -> None:
    """A caller's (m, 3) arrays in Fortran order (``np.array([xs, ys, zs]).T``) give the same
    linearisation as the same values in C order (the kernel reads rows)."""
    rng = np.random.default_rng(3)
    x, psi, a, s = _random_fov_case(rng, 8)
    x[0] += 0.5
    layout = avp.qp.layout.layout_for(3, 7)
    knots = np.array([0.0, 0.7, 1.4, 2.1])
    times = np.sort(rng.uniform(0.0, 2.1, 8))
    c_order = fov_blocks(layout, knots, times, x, psi, a, s, FovConfig())
    f_order = fov_blocks(layout, knots, times, np.asfortranarray(x), psi, np.asfortranarray(a), s, FovConfig())
    for name in ("h0", "reachable", "placed", "progress"):
        np.testing.assert_array_equal(getattr(f_order, name), getattr(c_order, name), err_msg=name)
    for b_c, b_f in zip(c_order.blocks, f_order.blocks, strict=True):
        np.testing.assert_array_equal(b_f.matrix, b_c.matrix)
        np.testing.assert_array_equal(b_f.upper, b_c.upper)


def test_fov_rows_of_integer_knots_and_times_are_those_of_their_values() -> None:
    """``fov_rows`` keys its cached point basis on the float64 bytes of the knots and times: a
    caller's integer knots (``FovRowInputs`` is public) give the rows of the same values as
    floats, and a second call with other times or rotor drag is not served the first one's
    basis."""
    from dataclasses import replace

    from avp.qp.fov import fov_rows

    layout = avp.qp.layout.layout_for(3, 7)
    for seed in range(50):  # the first case with points placed in two segments at least
        rng = np.random.default_rng(seed)
        x, psi, a, s = _random_fov_case(rng, 8)
        x[0] += 0.5
        rows = fov_blocks(layout, np.array([0.0, 1.0, 2.0, 3.0]), np.sort(rng.uniform(0.0, 3.0, 8)), x, psi, a, s,
                          FovConfig()).rows
        if rows is not None and np.unique(np.floor(rows.times)).size > 1:
            break
    assert rows is not None and np.unique(np.floor(rows.times)).size > 1
    floats = fov_rows(rows)
    integers = fov_rows(replace(rows, knots_rel=np.array([0, 1, 2, 3])))
    for b_f, b_i in zip(floats, integers, strict=True):
        np.testing.assert_array_equal(b_i.matrix, b_f.matrix)
    shifted = fov_rows(replace(rows, times=rows.times * 0.5))  # other times: another basis
    assert not np.array_equal(shifted[0].matrix, floats[0].matrix)
    with_drag = fov_rows(replace(rows, rotor_drag=0.3))  # the acceleration columns carry b2 + d b1
    assert not np.array_equal(with_drag[0].matrix, floats[0].matrix)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), policy=st.sampled_from(list(FovPointPolicy)),
       radii=st.tuples(*(st.sampled_from([0.05, 0.5, 2.0, math.inf]) for _ in range(3))),
       drag=st.sampled_from([0.0, 0.2, 0.7]), margin=st.sampled_from([0.0, 0.04]),
       n_seg=st.integers(1, 4), degree=st.sampled_from([5, 7]), m=st.integers(1, 12), build=st.booleans())
def test_rows_on_a_spline_equal_fov_blocks_at_its_points_bit_for_bit(
    seed: int, policy: FovPointPolicy, radii: tuple[float, float, float], drag: float, margin: float,
    n_seg: int, degree: int, m: int, build: bool,
) -> None:
    """``linearise_on_spline`` (one kernel call: evaluation, terms, rows) gives the same
    linearisation and blocks, bit for bit, as evaluating the spline with ``eval_spline`` and
    calling ``fov_blocks`` on the points (a + d v with rotor drag), whatever the policy, trust
    radii, drag or layout, with its blocks built in the call or on first access; and its blocks
    are those ``fov_rows`` builds from its row inputs."""
    from avp.frames import drag_acceleration
    from avp.qp.fov import fov_rows, linearise_on_spline
    from avp.qp.layout import layout_for

    rng = np.random.default_rng(seed)
    ref_knots = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 1.5, int(rng.integers(1, 4))))])
    coeffs = rng.normal(0.0, 1.0, (ref_knots.size - 1, 4, 8))
    coeffs[:, 2, 0] += 1.0
    reference = avp.Trajectory(coeffs, ref_knots)
    layout = layout_for(n_seg, degree)
    knots = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 1.5, n_seg))])
    times = np.sort(rng.uniform(0.0, knots[-1], m))
    tau = np.sort(rng.uniform(0.0, ref_knots[-1], m))
    s = rng.normal(0.0, 2.0, 3) + np.array([4.0, 0.0, 1.0])
    fov = FovConfig(point_policy=policy, trust_position=radii[0], trust_acceleration=radii[1], trust_yaw=radii[2],
                    margin=margin)
    new = linearise_on_spline(layout, knots, times, reference.coefficients, reference.knots_rel, tau, s, fov,
                              rotor_drag=drag, build_blocks=build)
    assert ("blocks" in new.__dict__) == build  # built in the call, or left to first access
    d = avp._avp_rust.eval_spline(reference.coefficients, reference.knots_rel, tau, [0, 1, 2])
    a0 = drag_acceleration(d[2, :, :3], d[1, :, :3], drag) if drag else d[2, :, :3]
    old = fov_blocks(layout, knots, times, d[0, :, :3], d[0, :, 3], a0, s, fov, rotor_drag=drag)
    for name in ("times", "h0", "reachable", "placed", "progress"):
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name), err_msg=name)
    assert new.hold_at_linearisation == old.hold_at_linearisation
    assert new.rows is not None and old.rows is not None
    for name in ("times", "gx", "ga", "gp", "rhs", "x0", "a0", "psi0"):
        u, v = getattr(new.rows, name), getattr(old.rows, name)
        assert u.shape == v.shape and np.array_equal(u, v), name
    assert new.rows.rotor_drag == old.rows.rotor_drag
    for built in (new.blocks, fov_rows(new.rows)):  # the blocks of the call (or of first access), and rebuilt
        assert [b.name for b in built] == [b.name for b in old.blocks]
        for b_new, b_old in zip(built, old.blocks, strict=True):
            for name in ("matrix", "lower", "upper"):
                u, v = getattr(b_new, name), getattr(b_old, name)
                assert u.shape == v.shape and np.array_equal(u, v), (b_new.name, name)


def test_rows_on_a_spline_check_their_times() -> None:
    """``linearise_on_spline`` takes one reference time per point: another count is a
    ``ConfigError`` naming ``tau`` (not a linearisation at the wrong times), and no point is the
    empty linearisation ``fov_blocks`` gives."""
    from avp.qp.fov import linearise_on_spline
    from avp.qp.layout import layout_for

    reference = avp.Trajectory(np.ones((1, 4, 8)), [0.0, 1.0])
    layout, knots = layout_for(1, 7), np.array([0.0, 1.0])
    args = (reference.coefficients, reference.knots_rel)
    for build in (True, False):
        with pytest.raises(ConfigError, match="^tau: one relative time"):
            linearise_on_spline(layout, knots, np.array([0.2, 0.4]), *args, np.array([0.2, 0.4, 0.6]),
                                np.array([3.0, 0.0, 1.0]), FovConfig(), build_blocks=build)
        none = linearise_on_spline(layout, knots, np.zeros(0), *args, np.zeros(0), np.array([3.0, 0.0, 1.0]),
                                   FovConfig(), build_blocks=build)
        same = fov_blocks(layout, knots, np.zeros(0), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)),
                          np.array([3.0, 0.0, 1.0]), FovConfig())
        assert none.times.size == 0 and none.blocks == () and none.hold_at_linearisation
        assert same.blocks == () and same.hold_at_linearisation
