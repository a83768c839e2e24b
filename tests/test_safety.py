"""Workspace safety (avp.safety, Rust regions.rs): certificates against exact rational oracles,
planted violations, returned plans checked on a dense grid, bad input, statuses."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp import _avp_rust
from avp.safety import certify_workspace

GRID = 5e-4  # s


def _spline(z_coeffs: list[float], T: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """One segment on [0, T]: x = t, y = 0, z = the given polynomial, yaw = 0."""
    c = np.zeros((1, 4, max(len(z_coeffs), 2)))
    c[0, 0, 1] = 1.0
    c[0, 2, : len(z_coeffs)] = z_coeffs
    return np.ascontiguousarray(c), np.array([0.0, T])


def _exact_min_positive(z: list[float], a: Fraction, b: Fraction, open_end: bool) -> bool:
    """Exact oracle: z(t) > 0 on [a, b] (or [a, b) when ``open_end``), with the float
    coefficients read as exact rationals."""
    t = sympy.Symbol("t", real=True)
    p = sum(sympy.Rational(Fraction(c)) * t**k for k, c in enumerate(z))
    A, B = sympy.Rational(a), sympy.Rational(b)
    if p.subs(t, A) <= 0:
        return False
    if not open_end and p.subs(t, B) <= 0:
        return False
    roots = sympy.Poly(p, t).real_roots() if sympy.Poly(p, t).degree() > 0 else []
    return not any(A <= r < B if open_end else A <= r <= B for r in roots)


@settings(max_examples=80)
@given(
    a=st.floats(0.05, 0.95),
    depth=st.floats(-1e-6, 1e-6).filter(lambda d: abs(d) > 1e-13),
    scale=st.sampled_from([1e-3, 1.0, 30.0]),
)
def test_halfspace_near_tangency_matches_exact_oracle(a: float, depth: float, scale: float) -> None:
    """z(t) = scale ((t - a)^2 + depth): the ground z > 0 holds iff depth > 0 (exactly, for the
    rational coefficients actually passed); the kernel's verdict agrees with sympy."""
    z = [scale * (a * a + depth), scale * (-2 * a), scale * 1.0]
    c, k = _spline(z)
    codes, _t, _res = _avp_rust.certify_halfspace(c, k, np.array([0.0, 0.0, 1.0]), 0.0, 0)
    expected = _exact_min_positive(z, Fraction(0), Fraction(1), open_end=False)
    assert (int(codes[0]) == 0) == expected


@settings(max_examples=80)
@given(
    a=st.floats(0.05, 0.9),
    depth=st.floats(-1e-6, 1e-6).filter(lambda d: abs(d) > 1e-12),
    rate=st.floats(0.05, 3.0),
)
def test_touching_plane_near_tangency_matches_exact_oracle(a: float, depth: float, rate: float) -> None:
    """z(t) = (1 - t) (rate ((t - a)^2 + depth) ...) touches z = 0 at contact t = 1 and is
    positive before exactly when the quotient is: the reflected certificate agrees with the
    exact oracle on [0, 1)."""
    q = np.polynomial.polynomial.polymul([1.0, -1.0], [rate * (a * a + depth), rate * (-2 * a), rate])
    z = [float(x) for x in q]
    c, k = _spline(z)
    codes, _t, residual = _avp_rust.certify_halfspace(c, k, np.array([0.0, 0.0, 1.0]), 0.0, 1)
    # the float product is not exactly (1 - t) q(t): the oracle judges what was passed, up to the
    # certified contact residual (a proven WITHIN means z > -residual everywhere)
    if int(codes[0]) == 0:
        ts = np.linspace(0.0, 1.0, 20001)
        assert np.polynomial.polynomial.polyval(ts, z).min() > -residual - 1e-15
        assert residual < 1e-12
    if depth > 1e-9:  # clearly positive before contact: must be proven
        assert int(codes[0]) == 0
    if depth < -1e-9:  # clearly dips below before contact: must be refuted
        assert int(codes[0]) == 1


def test_touching_plane_catches_a_departing_contact_velocity() -> None:
    """z = t (1 - t) reaches z = 0 at t = 1 moving down but started at 0 (on the plane); z = -(1-t)
    is below the plane all the way: both violated; z = (1 - t)^2 (tangential) needs order 2."""
    plane = np.array([0.0, 0.0, 1.0])
    c, k = _spline([-1.0, 1.0])
    assert int(_avp_rust.certify_halfspace(c, k, plane, 0.0, 1)[0][0]) == 1
    c, k = _spline([1.0, -2.0, 1.0])
    assert int(_avp_rust.certify_halfspace(c, k, plane, 0.0, 1)[0][0]) == 1  # Q(0) = 0: unproven
    assert int(_avp_rust.certify_halfspace(c, k, plane, 0.0, 2)[0][0]) == 0


def test_sphere_and_speed_match_exact_oracles() -> None:
    # x = t, z = 0.5: distance to (0.5, 0, 0.5 - r0) ... straight line at height 0.5 past a ball
    for r0, inside in ((0.49, False), (0.5, True), (0.51, True)):
        c, k = _spline([0.5])
        codes, _, _ = _avp_rust.certify_sphere_outside(c, k, np.array([0.5, 0.0, 0.0]), r0)
        assert (int(codes[0]) == 1) == inside  # touching counts as violated
    c, k = _spline([0.0, 0.0, 1.0])  # v = (1, 0, 2t): |v|^2 = 1 + 4 t^2, max 5 at t = 1
    assert int(_avp_rust.certify_speed(c, k, math.sqrt(5.0) * (1 + 1e-12))[0][0]) == 0
    assert int(_avp_rust.certify_speed(c, k, math.sqrt(5.0) * (1 - 1e-12))[0][0]) == 1


# -- planner level -----------------------------------------------------------------------------
def _scenario(incline_deg: float, stand: float, lateral: float, lift: float, speed: float,
              heading: float, yaw: float, yaw_rate: float) -> tuple[avp.State, avp.PerchTarget]:
    inc = math.radians(incline_deg)
    target = avp.PerchTarget.from_incline([0.0, 0.0, 3.0], inc)
    # a start on the outward side, above the ground (z = 0), at the given stand-off
    p0 = target.point + stand * target.s3 + lateral * target.s2 + lift * np.array([0.0, 0.0, 1.0])
    p0[2] = max(p0[2], 0.3)
    if (p0 - target.point) @ target.s3 < 0.3:
        p0 = p0 + (0.3 - (p0 - target.point) @ target.s3) * target.s3
        p0[2] = max(p0[2], 0.3)
    v0 = speed * np.array([math.cos(heading), math.sin(heading), 0.0])
    return avp.State(position=p0, velocity=v0, yaw=yaw, yaw_rate=yaw_rate), target


@settings(max_examples=25)
@given(
    incline=st.floats(0.0, 180.0),
    stand=st.floats(1.0, 8.0),
    lateral=st.floats(-2.0, 2.0),
    lift=st.floats(-1.0, 2.0),
    speed=st.floats(0.0, 3.0),
    heading=st.floats(-math.pi, math.pi),
    yaw=st.floats(-math.pi, math.pi),
    yaw_rate=st.floats(-2.0, 2.0),
)
def test_returned_plans_keep_clearance_and_ground_on_a_dense_grid(
    incline: float, stand: float, lateral: float, lift: float, speed: float, heading: float,
    yaw: float, yaw_rate: float,
) -> None:
    state, target = _scenario(incline, stand, lateral, lift, speed, heading, yaw, yaw_rate)
    if (state.position - target.point) @ target.s3 <= 1e-6:
        return  # the lift pushed the start behind a steep overhang: rejected, tested below
    config = avp.PlannerConfig(workspace=avp.Workspace(ground_z=0.0))
    result = avp.plan_detailed(state, target, config)
    traj = result.trajectory
    if not result.ok:
        assert result.status is not avp.PlanStatus.SOLVED
        return
    assert traj is not None and result.safety is not None and result.safety.certified
    assert traj.provenance is not None and traj.provenance.workspace_certified and traj.provenance.bounds_certified
    assert (result.status is avp.PlanStatus.SOLVED_RELAXED) == bool(result.relaxations)
    ts = np.arange(traj.t0, traj.tf, GRID)
    p = traj(ts)
    assert np.all((p - target.point) @ target.s3 > 0.0)
    assert np.all(p[:, 2] > 0.0)


def test_each_planted_violation_is_reported() -> None:
    """Take a certified plan and plant each limit just inside its path: VIOLATED, named."""
    state = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90))
    traj = avp.plan(state, target)
    ts = np.arange(traj.t0, traj.tf, GRID)
    p, v = traj(ts), traj(ts, 1)
    i = int(np.argmin(p[:, 2]))
    planted = [
        ("ground", avp.Workspace(ground_z=float(p[:, 2].min()) + 0.01)),
        ("max speed", avp.Workspace(max_speed=0.99 * float(np.linalg.norm(v, axis=1).max()))),
        ("half-space 0", avp.Workspace(half_spaces=(avp.HalfSpace(point=p[i] + [0, 0, 0.01], normal=[0, 0, 1]),))),
        ("sphere 0", avp.Workspace(spheres=(avp.Sphere(center=p[len(ts) // 2], radius=0.05),))),
    ]
    for name, ws in planted:
        report = certify_workspace(traj, target, ws)
        assert not report.certified and name in report.failed, report
        check = next(c for c in report.checks if c.region.name == name)
        assert check.verdicts and any(v is avp.Certificate.VIOLATED for v in check.verdicts)
    # and the same plan, with room to spare, is proven
    ok = avp.Workspace(ground_z=float(p[:, 2].min()) - 0.01,
                       max_speed=1.01 * float(np.linalg.norm(v, axis=1).max()))
    assert certify_workspace(traj, target, ok).certified


def test_refinement_repairs_a_speed_limit_and_the_status_names_what_failed() -> None:
    state = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90))
    first = avp.plan(state, target)
    peak = float(np.linalg.norm(first(np.linspace(first.t0, first.tf, 400), 1), axis=1).max())
    limit = 0.93 * peak  # above the 2.02 m/s contact speed and the start
    no_refine = avp.PlannerConfig(
        workspace=avp.Workspace(max_speed=limit, refinement_rounds=0),
        bounds=avp.BoundsPolicy(factors=(), relaxations=()),
    )
    result = avp.plan_detailed(state, target, no_refine)
    assert result.status is avp.PlanStatus.WORKSPACE_NOT_CERTIFIED and not result.ok
    assert result.safety is not None and result.safety.failed == ["max speed"]
    assert any("max speed could not be met" in line for line in result.log)
    with pytest.raises(avp.WorkspaceNotCertifiedError):
        avp.plan(state, target, no_refine)
    refined = avp.plan_detailed(state, target, avp.PlannerConfig(workspace=avp.Workspace(max_speed=limit)))
    assert refined.ok and refined.safety is not None and refined.safety.certified
    ts = np.arange(refined.trajectory.t0, refined.trajectory.tf, GRID)
    assert np.linalg.norm(refined.trajectory(ts, 1), axis=1).max() < limit


def test_the_search_never_trades_the_workspace_away() -> None:
    """A floor pad 2 m ahead of a start 1 m above it, with the paper's alpha = 4: clearance and
    the band (14) conflict; whatever comes back keeps the floor."""
    state = avp.State.hover([0.0, 0.0, 1.0])
    target = avp.PerchTarget.from_incline([2.0, 0.0, 0.0], 0.0)
    for alpha in (None, 4.0):
        result = avp.plan_detailed(state, target, avp.PlannerConfig(alpha=alpha, workspace=avp.Workspace(ground_z=0.0)))
        if result.ok:
            ts = np.arange(result.trajectory.t0, result.trajectory.tf, GRID)
            assert result.trajectory(ts)[:, 2].min() > 0.0
        if alpha is None:  # the default contact thrust makes it a plain solve
            assert result.status in (avp.PlanStatus.SOLVED, avp.PlanStatus.SOLVED_WITHOUT_FOV), result.log


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: (avp.State.hover([4.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90)),
                  avp.Workspace()), "state.position"),
        (lambda: (avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, -0.5], math.radians(90)),
                  avp.Workspace(ground_z=0.0)), "target.point"),
        (lambda: (avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90)),
                  avp.Workspace(ground_z=1.5)), "state.position"),
        (lambda: (avp.State(position=[0.0, 0.0, 1.5], velocity=[3.0, 0, 0]),
                  avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90)), avp.Workspace(max_speed=2.5)),
         "state.velocity"),
        (lambda: (avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90)),
                  avp.Workspace(spheres=(avp.Sphere(center=[0.0, 0.0, 1.6], radius=0.5),))), "state.position"),
    ],
)
def test_endpoints_outside_the_workspace_are_config_errors(make, field: str) -> None:
    state, target, ws = make()
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan_detailed(state, target, avp.PlannerConfig(workspace=ws))
    assert exc.value.field == field


def test_workspace_config_rejects_bad_values() -> None:
    with pytest.raises(avp.ConfigError, match="workspace.body_offset"):
        avp.Workspace(body_offset=-0.1)
    with pytest.raises(avp.ConfigError, match="workspace.ground_z"):
        avp.Workspace(ground_z=float("nan"))
    with pytest.raises(avp.ConfigError, match="workspace.half_spaces.normal"):
        avp.HalfSpace(point=[0, 0, 0], normal=[0, 0, 0])
    with pytest.raises(avp.ConfigError, match="workspace.spheres.radius"):
        avp.Sphere(center=[0, 0, 0], radius=0.0)
    with pytest.raises(avp.ConfigError, match="workspace.half_spaces"):
        avp.Workspace(half_spaces=([0, 0, 1],))  # type: ignore[arg-type]


def test_body_offset_moves_contact_out_along_the_normal_and_keeps_the_distance() -> None:
    state = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(60))
    cfg = avp.PlannerConfig(workspace=avp.Workspace(body_offset=0.08))
    traj = avp.plan(state, target, cfg)
    assert np.linalg.norm(traj(traj.tf) - (target.point + 0.08 * target.s3)) < 1e-9
    ts = np.arange(traj.t0, traj.tf, GRID)
    assert np.all((traj(ts) - target.point) @ target.s3 > 0.08)


def test_grid_position_rows_equal_the_rows_at_the_sample_times() -> None:
    """The cached workspace rows (independent of the durations) against rows evaluated at the
    sample times of unequal segments: equal as polynomial values at every sample (a sample on an
    interior knot may sit at the end of one segment or the start of the next: the same value
    for a continuous spline), checked on random continuous splines."""
    import numpy as np

    from avp import safety
    from avp.qp.layout import layout_for
    from avp.qp.rows import vector_rows

    layout = layout_for(3, 7)
    rng = np.random.default_rng(2)
    for per_segment in (2, 5):
        knots = np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 1.5, 3))])
        times = safety._sample_times(knots, per_segment)
        cached = safety._grid_position_rows(3, 7, per_segment)
        direct = vector_rows(layout, knots, 0, times)
        assert cached.shape == direct.shape
        # a random spline in the decision space, made C^3-continuous by least squares on the
        # continuity rows' null space, evaluates the same through both row sets
        from avp.qp.boundary import continuity_rows
        C = continuity_rows(layout, np.diff(knots), 3, float(np.mean(np.diff(knots))))
        _, _, Vt = np.linalg.svd(C)
        Z = Vt[np.linalg.matrix_rank(C):].T
        c = Z @ rng.normal(size=Z.shape[1])
        np.testing.assert_allclose(np.einsum("min,n->mi", cached, c), np.einsum("min,n->mi", direct, c),
                                   rtol=1e-9, atol=1e-9)


def test_regions_leave_the_callers_arrays_writable() -> None:
    """The regions are shared by later calls (read-only copies); the workspace's own vectors are
    not frozen by planning with them."""
    from avp.safety import regions_for

    ws = avp.Workspace(half_spaces=(avp.HalfSpace(point=(0.0, 0.0, 3.0), normal=(0.0, 0.0, -1.0)),),
                       spheres=(avp.Sphere(center=(1.0, 2.0, 1.0), radius=0.3),))
    before = [ws.half_spaces[0].normal.flags.writeable, ws.spheres[0].center.flags.writeable]
    target = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(90.0))
    regions = regions_for(target, ws)
    assert regions_for(target, ws) is regions  # the last call's regions, by identity
    assert all(not r.normal.flags.writeable for r in regions)
    assert [ws.half_spaces[0].normal.flags.writeable, ws.spheres[0].center.flags.writeable] == before


def test_workspace_limits_compare_by_value_and_survive_a_config_file() -> None:
    """HalfSpace and Sphere hold arrays: the generated == raised ("truth value of an array is
    ambiguous") and hash failed, so a configuration with a ceiling could not be compared with
    itself loaded back from its mapping."""
    from avp.configfile import from_mapping, to_mapping

    def config(radius: float) -> avp.PlannerConfig:
        return avp.PlannerConfig(workspace=avp.Workspace(
            half_spaces=(avp.HalfSpace(point=[0.0, 0.0, 4.0], normal=[0.0, 0.0, -1.0]),),
            spheres=(avp.Sphere(center=[1.5, 0.8, 1.5], radius=radius),)))

    a = config(0.3)
    assert a == config(0.3) and hash(a) == hash(config(0.3)) and a != config(0.4)
    assert from_mapping(avp.PlannerConfig, to_mapping(a), "planner") == a
