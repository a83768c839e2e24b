"""Line perches (avp.line, avp.qp.line, avp.line_certify, avp.line_planner).

Contact conditions and clearance are checked by independent evaluation of the returned splines
(not by the planner's own rows); the clearance certificate is checked against an exact sympy
oracle built from the same f64 inputs.
"""

from __future__ import annotations

import math
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp.bounds import Certificate
from avp.config import PlannerConfig, VehicleLimits, Workspace
from avp.errors import ConfigError
from avp.line import LineTarget, LineYaw
from avp.line_certify import DyadicPoly, PolyCheck, clearance_poly, position_polys, run_checks
from avp.line_planner import LineOptions, LineStatus, plan_line, reversed_trajectory
from avp.trajectory import Trajectory

# A 0.8 kg vehicle with thrust-to-weight 4 (Paneque et al.'s), default tilt-rate limit 10 rad/s.
LIMITS = VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81)
CFG = PlannerConfig(limits=LIMITS)


def with_ground(z: float) -> PlannerConfig:
    return PlannerConfig(limits=LIMITS, workspace=Workspace(ground_z=z))


def horizontal_line(z: float = 2.5, incline_deg: float = 0.0, x: float = 3.0, **kw: object) -> LineTarget:
    a = math.radians(incline_deg)
    half = np.array([0.0, 1.5 * math.cos(a), 1.5 * math.sin(a)])
    c = np.array([x, 0.0, z])
    return LineTarget.segment(c - half, c + half, **kw)  # type: ignore[arg-type]


def sampled_distance(traj: Trajectory, line: LineTarget, n: int = 2000) -> np.ndarray:
    tt = np.linspace(traj.t0, traj.tf, n)
    return np.array([line.distance(p) for p in traj(tt)])


def check_contact(res, line: LineTarget) -> None:
    """Gripper within 1 mm of the grasp point on the line, b3 within 0.5 deg of n, speed within
    1 mm/s of the request (the contact tolerances of docs/lines.md), from the spline itself."""
    tr = res.perch
    R = tr.attitude(tr.tf)
    b3 = R[:, 2]
    n = res.contact.n
    assert math.degrees(math.acos(min(1.0, float(b3 @ n)))) < 0.5
    gripper = tr(tr.tf) - line.gripper_offset * b3
    assert line.distance(gripper) < 1e-3
    if line.grasp is not None:
        assert np.linalg.norm(gripper - res.contact.grasp_point(line.grasp)) < 1e-3
    assert np.linalg.norm(tr(tr.tf, 1) + line.contact_speed * n) < 1e-3


@settings(max_examples=12)
@given(
    pitch=st.sampled_from([0.0, 20.0, 45.0, 80.0, 120.0, 180.0]),
    incline=st.floats(0.0, 25.0),
    dx=st.floats(-2.5, -1.5),
    dz=st.floats(-0.8, 0.8),
    lam=st.floats(0.2, 0.8),
)
def test_terminal_conditions_and_clearance_on_random_lines(pitch: float, incline: float, dx: float, dz: float, lam: float) -> None:
    line = horizontal_line(z=3.0, incline_deg=incline, pitch=math.radians(pitch), grasp=lam)
    start = np.array([3.0 + dx, 0.3, 3.0 + dz - (1.2 if pitch > 90 else 0.0)])
    res = plan_line(avp.State.hover(start), line, with_ground(0.5))
    if pitch <= 90.0:
        assert res.status is LineStatus.SOLVED, res.log
    if res.perch is None:
        return
    check_contact(res, line)
    if res.ok:
        # Certified clearance: independent dense sampling must agree (to the reported slack).
        for traj in (res.perch, res.recovery):
            d = sampled_distance(traj, line)
            assert d.min() >= line.gripper_offset - 1e-6
            assert traj(np.linspace(traj.t0, traj.tf, 500))[:, 2].min() >= 0.5
        assert res.clearance_slack < 1e-9


def _exact_max_on(F: sp.Poly, a: sp.Rational, b: sp.Rational) -> sp.Rational:
    u = F.gens[0]
    crit = [r for r in sp.Poly(F.diff(u), u).real_roots() if a <= r <= b]
    return max([F.eval(a), F.eval(b)] + [F.eval(r) for r in crit])


def _sympy_clearance(traj: Trajectory, seg: int, A: np.ndarray, B: np.ndarray, r: float) -> sp.Poly:
    """The exact clearance polynomial in u, built independently with sympy rationals."""
    u = sp.symbols("u")
    t0, t1 = sp.Rational(Fraction(float(traj.knots[seg]))), sp.Rational(Fraction(float(traj.knots[seg + 1])))
    T = t1 - t0
    p = [sum(sp.Rational(Fraction(float(c))) * (T * u) ** k for k, c in enumerate(traj.coefficients[seg, a])) for a in range(3)]
    Ar = [sp.Rational(Fraction(float(x))) for x in A]
    v = [sp.Rational(Fraction(float(B[i]))) - Ar[i] for i in range(3)]
    e = [p[i] - Ar[i] for i in range(3)]
    cr = [e[1] * v[2] - e[2] * v[1], e[2] * v[0] - e[0] * v[2], e[0] * v[1] - e[1] * v[0]]
    rr = sp.Rational(Fraction(r)) ** 2
    return sp.Poly(sp.expand(rr * sum(x * x for x in v) - sum(c * c for c in cr)), u)


@settings(max_examples=12)
@given(
    eps_exp=st.integers(-13, -4),
    sign=st.sampled_from([-1, 0, 1]),
    yaw=st.floats(0.0, 2 * math.pi),
    tilt=st.floats(-0.4, 0.4),
)
def test_clearance_certificate_matches_exact_oracle_near_tangency(eps_exp: int, sign: int, yaw: float, tilt: float) -> None:
    """A parabola that passes at distance r + sign * 10^eps_exp from an inclined line."""
    r = 0.12
    d = np.array([math.cos(yaw) * math.cos(tilt), math.sin(yaw) * math.cos(tilt), math.sin(tilt)])
    up = np.array([0.0, 0.0, 1.0]) - d[2] * d
    up /= np.linalg.norm(up)
    side = np.cross(d, up)
    A = np.array([0.3, -0.2, 1.0])
    B = A + 2.0 * d
    # p(t) = A + d (t - 0.4) + up (r + delta + (t - 1)^2) + 0.5 side (t - 1)^2: min distance r + delta at t = 1
    delta = sign * 10.0**eps_exp
    coeffs = np.zeros((1, 4, 3))
    # (t - 1)^2 = 1 - 2t + t^2
    for ax in range(3):
        coeffs[0, ax] = [A[ax] - 0.4 * d[ax] + up[ax] * (r + delta + 1.0) + 0.5 * side[ax],
                         d[ax] - 2.0 * up[ax] - side[ax], up[ax] + 0.5 * side[ax]]
    traj = Trajectory(coeffs, [0.0, 2.0])
    F, scale = clearance_poly(position_polys(traj, 0), A, B, r)
    (cert,) = run_checks([PolyCheck("clearance", "t", 0, F, scale=scale)], {"t": traj.knots})
    exact_poly = _sympy_clearance(traj, 0, A, B, r)
    exact = _exact_max_on(exact_poly, sp.Integer(0), sp.Integer(1))
    # The dyadic construction is the same polynomial as the sympy one, coefficient by coefficient.
    ref = exact_poly.all_coeffs()[::-1]
    mine = [sp.Rational(c, 2**F.e) for c in F.c]
    assert ref == mine[: len(ref)] and all(m == 0 for m in mine[len(ref):])
    # Sound: WITHIN only if the exact maximum is negative. Nearly complete: VIOLATED only if the
    # exact maximum is within the upward rounding of the coefficients (sum of the gaps) of 0.
    rounding = sum(sp.Rational(Fraction(float(h))) - m for h, m in zip(F.upper_floats(), mine, strict=True))
    if cert.verdict is Certificate.WITHIN:
        assert exact < 0
    else:
        assert cert.verdict is Certificate.VIOLATED
        assert exact >= -rounding
    if sign != 0 and eps_exp >= -8:  # far from tangency: the verdict is the exact one
        assert (cert.verdict is Certificate.WITHIN) == (sign > 0)


@settings(max_examples=8)
@given(dz=st.floats(-0.3, 0.3), dy=st.floats(-0.6, 0.6))
def test_contact_root_certificate_is_sound_against_exact_evaluation(dz: float, dy: float) -> None:
    """Contact at distance r (a double root at t_f): the certified statement ``F < slack`` on the
    last segment is checked by exact rational evaluation of the sympy-built polynomial on a grid
    that accumulates at the contact (where floating point cannot tell F from 0)."""
    line = horizontal_line(z=2.0, pitch=0.0)
    res = plan_line(avp.State.hover([2.0, dy, 2.6 + dz]), line, CFG, LineOptions(recovery=False))
    tr = res.perch
    assert tr is not None and res.ok, res.log
    A, B = line.piece(0)
    seg = tr.n_segments - 1
    F = _sympy_clearance(tr, seg, A, B, line.gripper_offset)
    coeffs = [Fraction(int(c.p), int(c.q)) for c in F.all_coeffs()[::-1]]
    clear = next(c for c in res.certificates if c.name == "clearance piece 0" and c.segment == seg)
    assert clear.ok
    vv = sum(Fraction(float(x)) ** 2 for x in (B - A))
    bound = Fraction(clear.slack) * vv  # slack is in m^2, F in m^2 |v|^2
    grid = [Fraction(k, 64) for k in range(64)] + [1 - Fraction(1, 2**k) for k in range(7, 40)]
    for u in grid:
        assert sum(c * u**k for k, c in enumerate(coeffs)) < bound
    # and F really is near 0 at contact (the slack is the QP's tiny equality residual)
    assert abs(sum(coeffs)) < Fraction(1, 10**9)


def test_certificate_rejects_a_path_through_the_clearance_radius() -> None:
    line = horizontal_line(z=2.0)
    A, B = line.piece(0)
    # Straight flight through the line's axis at t = 0.5.
    coeffs = np.zeros((1, 4, 2))
    coeffs[0, :3, 0] = [3.0, 0.0, 1.0]
    coeffs[0, 2, 1] = 2.0
    traj = Trajectory(coeffs, [0.0, 1.0])
    F, scale = clearance_poly(position_polys(traj, 0), A, B, line.gripper_offset)
    (cert,) = run_checks([PolyCheck("clearance", "t", 0, F, scale=scale)], {"t": traj.knots})
    assert cert.verdict is Certificate.VIOLATED
    assert 0.3 < cert.t < 0.7


def test_an_uncertified_line_plan_does_not_claim_a_trajectory() -> None:
    # A start right under the line: the last perch the search made comes within 0.1 mm of the
    # line's axis (0.15 m is the clearance asked), so nothing is certified. Code that handles
    # every planner's result alike (``if result.status.has_trajectory: fly(result.trajectory)``)
    # must not fly it: has_trajectory means a certified plan, as for a pad.
    line = LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=0.0, gripper_offset=0.15)
    res = plan_line(avp.State.hover([2.0, 0.0, 2.5]), line)
    assert res.status is LineStatus.NOT_CERTIFIED and not res.ok
    assert not res.status.has_trajectory
    assert res.perch is not None  # kept for diagnostics
    d = sampled_distance(res.perch, line)
    assert d.min() < line.gripper_offset  # the reason: it does pass inside the clearance radius
    assert [s.has_trajectory for s in LineStatus] == [s is LineStatus.SOLVED for s in LineStatus]


@pytest.mark.parametrize("pitch,point", [
    (math.pi, (5.0, 0.0, 3.0)),   # upside down: the perch flown backwards ends at the start, not here
    (0.0, (2.0, 0.0, 3.7)),       # on the wire itself: no recovery can end there
    (0.0, (2.0, 0.0, 4.5)),
    (0.0, (0.0, 0.0, 2.5)),       # the start: the perch flown backwards does end there
])
def test_a_given_recovery_point_is_where_a_solved_recovery_ends(pitch: float, point: tuple[float, float, float]) -> None:
    """``LineOptions.recovery_point`` is a request: a SOLVED plan's recovery ends there (checked
    by evaluating the spline), or the status is not SOLVED. The perch flown backwards, which
    ends at the perch's start, used to stand in for it with SOLVED."""
    line = LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=pitch, gripper_offset=0.15)
    config = PlannerConfig(limits=VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81))
    res = plan_line(avp.State.hover([0.0, 0.0, 2.5]), line, config, LineOptions(recovery_point=point))
    if point == (2.0, 0.0, 3.7):
        assert res.status is LineStatus.NOT_CERTIFIED
    else:  # each of the others has a certified recovery to the point
        assert res.status is LineStatus.SOLVED, res.log
    if res.ok:
        assert res.recovery is not None
        np.testing.assert_allclose(res.recovery.evaluate(res.recovery.tf)[:3], point, atol=1e-6)
        np.testing.assert_allclose(res.recovery.evaluate(res.recovery.tf, 1)[:3], 0.0, atol=1e-6)  # at rest


def test_a_given_recovery_point_is_not_moved_by_the_ground_margin() -> None:
    """Only the default hover point is raised to ``ground_z + recovery_height_margin``: the start
    given as the recovery point stays the start (the perch flown backwards ends there), and a
    given point at or below the ground is bad input."""
    line = LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=math.pi, gripper_offset=0.15)
    config = PlannerConfig(limits=VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81),
                           workspace=Workspace(ground_z=1.0))
    start = (0.0, 0.0, 2.5)
    res = plan_line(avp.State.hover(start), line, config, LineOptions(recovery_point=start, recovery_height_margin=1.6))
    assert res.ok and res.recovery is not None, res.log
    np.testing.assert_allclose(res.recovery.evaluate(res.recovery.tf)[:3], start, atol=1e-6)
    with pytest.raises(ConfigError) as exc:
        plan_line(avp.State.hover(start), line, config, LineOptions(recovery_point=(5.0, 0.0, 1.0)))
    assert exc.value.field == "options.recovery_point"


@settings(max_examples=10)
@given(x0=st.floats(-1.0, 1.0), y0=st.floats(-0.6, 0.6), lo=st.floats(0.1, 0.4), width=st.floats(0.05, 0.3))
def test_free_grasp_point_stays_on_the_segment(x0: float, y0: float, lo: float, width: float) -> None:
    hi = lo + width
    line = LineTarget.segment([-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], grasp=None, grasp_range=(lo, hi),
                              yaw=LineYaw.FREE, gripper_offset=0.08)
    res = plan_line(avp.State.hover([x0, y0, 1.6]), line, CFG, LineOptions(recovery=False))
    assert res.status is LineStatus.SOLVED, res.log
    assert lo - 1e-9 <= res.grasp <= hi + 1e-9
    tr = res.perch
    gripper = tr(tr.tf) - line.gripper_offset * tr.attitude(tr.tf)[:, 2]
    assert line.distance(gripper) < 1e-6
    assert abs(res.contact.grasp_fraction(gripper) - res.grasp) < 1e-6


def test_free_grasp_point_goes_where_it_is_cheapest() -> None:
    """A start above one end: the free grasp point moves towards it, and its snap cost (4),
    integrated independently on a dense grid, is below the fixed midpoint's at the same duration."""
    ends = ([-1.0, 0.0, 1.0], [1.0, 0.0, 1.0])
    free = LineTarget.segment(*ends, grasp=None, grasp_range=(0.0, 1.0), yaw=LineYaw.FREE)
    fixed = LineTarget.segment(*ends, grasp=0.5, yaw=LineYaw.FREE)
    st0 = avp.State.hover([0.8, 0.0, 1.8])
    rf = plan_line(st0, free, CFG, LineOptions(recovery=False), duration=1.5)
    rx = plan_line(st0, fixed, CFG, LineOptions(recovery=False), duration=1.5)
    assert rf.grasp > 0.6

    def snap_cost(tr: Trajectory) -> float:
        t = np.linspace(tr.t0, tr.tf, 20001)
        s4 = np.sum(tr(t, 4) ** 2, axis=1)
        return float(np.sum((s4[1:] + s4[:-1]) / 2.0 * np.diff(t)))

    assert rf.perch.duration == rx.perch.duration
    assert snap_cost(rf.perch) < snap_cost(rx.perch)


@pytest.mark.parametrize("pitch", [0.0, 80.0, 180.0])
def test_recovery_is_continuous_up_to_snap_and_certified(pitch: float) -> None:
    line = horizontal_line(z=3.7 if pitch == 180 else 2.5, pitch=math.radians(pitch))
    start = [1.0, 0.0, 2.2 if pitch == 180 else 2.6]
    res = plan_line(avp.State.hover(start), line, with_ground(0.8))
    assert res.ok, res.log
    p, r = res.perch, res.recovery
    assert r.t0 == p.tf
    a = p.derivatives(p.tf)
    b = r.derivatives(r.t0)
    scale = np.maximum(1.0, np.abs(a))
    assert np.all(np.abs(a - b) / scale < 1e-6)
    assert np.linalg.norm(r(r.tf, 1)) < 1e-6 and np.linalg.norm(r(r.tf, 2)) < 1e-6
    assert all(c.ok for c in res.certificates if c.trajectory == "recovery")
    assert res.recovery_bounds is not None and res.recovery_bounds.certified


def test_reversed_trajectory_runs_backwards() -> None:
    res = plan_line(avp.State.hover([1.0, 0.0, 2.6]), horizontal_line(pitch=math.radians(80)), CFG, LineOptions(recovery=False))
    p = res.perch
    back = reversed_trajectory(p, p.tf)
    s = np.linspace(0.0, p.duration, 37)
    for order in range(5):
        assert np.allclose(back(p.tf + s, order), (-1) ** order * p(p.tf - s, order), atol=1e-7)


def test_wedge_and_heading_when_landing_on_top() -> None:
    line = LineTarget.segment([-3.0, 0.0, 1.0], [3.0, 0.0, 1.0], pitch=0.0, yaw=LineYaw.ALONG, gripper_offset=0.1)
    opts = LineOptions(wedge_angle=math.radians(60.0), wedge_window=0.5)
    res = plan_line(avp.State.hover([-1.3, 0.4, 2.2], yaw=math.radians(25)), line, CFG, opts)
    assert res.ok, res.log
    tr = res.perch
    tt = np.linspace(tr.tf - 0.5, tr.tf, 400)
    rel = tr(tt) - np.array([0.0, 0.0, 1.0])
    angle = np.degrees(np.arctan2(np.abs(rel[:, 1]), rel[:, 2]))
    assert angle.max() <= 30.0 + 1e-9
    b1 = tr.attitude(tr.tf)[:, 0]
    assert abs(b1 @ np.array([1.0, 0.0, 0.0])) > math.cos(math.radians(0.5))


def test_start_perched_on_the_line_takes_off() -> None:
    line = LineTarget.segment([-3.0, 0.0, 1.0], [3.0, 0.0, 1.0], pitch=0.0, yaw=LineYaw.ALONG, gripper_offset=0.1)
    res = plan_line(avp.State.hover([-1.5, 0.0, 1.1]), line, CFG, LineOptions(recovery=False))
    assert res.ok, res.log
    assert sampled_distance(res.perch, line).min() >= 0.1 - 1e-9


def test_catenary_vertices_lie_on_a_sagging_cable() -> None:
    line = LineTarget.catenary([0.0, 0.0, 5.0], [10.0, 0.0, 5.0], sag=0.5, pieces=10)
    z = line.vertices[:, 2]
    assert abs(z.min() - 4.5) < 1e-9 and z[0] == 5.0 and z[-1] == 5.0
    assert np.all(np.diff(z[:6]) < 0) and np.all(np.diff(z[5:]) > 0)


def test_dyadic_arithmetic_is_exact() -> None:
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=5), rng.normal(size=4)
    P, Q = DyadicPoly.from_floats(a.tolist()), DyadicPoly.from_floats(b.tolist())
    prod = P * Q
    ref = [sum(Fraction(a[i]) * Fraction(b[k - i]) for i in range(len(a)) if 0 <= k - i < len(b)) for k in range(8)]
    assert [Fraction(c, 2**prod.e) for c in prod.c] == ref
    shifted = P.shift(1)
    ref_s = [sum(Fraction(a[k]) * math.comb(k, j) for k in range(j, 5)) for j in range(5)]
    assert [Fraction(c, 2**shifted.e) for c in shifted.c] == ref_s
    up = prod.upper_floats()
    assert all(Fraction(float(x)) >= y for x, y in zip(up, ref, strict=True))


@settings(max_examples=40)
@given(
    a=st.lists(st.floats(-1e8, 1e8, allow_subnormal=False), min_size=1, max_size=15),
    b=st.lists(st.floats(-1e8, 1e8, allow_subnormal=False), min_size=1, max_size=15),
)
def test_dyadic_product_matches_fractions(a: list[float], b: list[float]) -> None:
    """The exact product on integers with a shared exponent against Fractions."""
    prod = DyadicPoly.from_floats(a) * DyadicPoly.from_floats(b)
    ref = [sum(Fraction(a[i]) * Fraction(b[k - i]) for i in range(len(a)) if 0 <= k - i < len(b))
           for k in range(len(a) + len(b) - 1)]
    assert [Fraction(c, 2**prod.e) for c in prod.c] == ref


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"vertices": [[0, 0, 1], [0, 0, 1]]}, "line.vertices"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "pitch": math.radians(181)}, "line.pitch"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "pitch": -0.1}, "line.pitch"),
        ({"vertices": [[0, 0, 1], [1, 0, float("nan")]]}, "line.vertices"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "pitch": float("nan")}, "line.pitch"),
        ({"vertices": [[0, 0, 1], [0, 0, 3]]}, "line.vertices"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "grasp": 1.5}, "line.grasp"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "gripper_offset": 0.01, "radius": 0.02}, "line.gripper_offset"),
        ({"vertices": [[0, 0, 1], [1, 0, 1]], "contact_speed": -1.0}, "line.contact_speed"),
    ],
)
def test_bad_line_input(kwargs: dict, field: str) -> None:
    with pytest.raises(ConfigError) as exc:
        LineTarget(**kwargs)
    assert exc.value.field == field


@pytest.mark.parametrize("duration", [1e-9, 1e-7, 1e-6])
def test_a_far_too_short_duration_is_an_uncertified_result(duration: float) -> None:
    """The recovery started from the uncertified perch's end, a State beyond the limits of a
    flight: a ConfigError on ``state.acceleration`` / ``state.jerk``, fields the caller never
    passed. Now NOT_CERTIFIED without a recovery, saying why (as 1e-3 s already was)."""
    line = LineTarget.segment([3, -1.5, 2.5], [3, 1.5, 2.5])
    res = plan_line(avp.State.hover([0, 0, 1.5]), line, duration=duration)
    assert res.status is LineStatus.NOT_CERTIFIED and res.recovery is None
    assert any(entry.startswith("recovery: not planned: the perch's end") for entry in res.log)


def test_start_inside_the_clearance_radius_is_rejected() -> None:
    line = LineTarget.segment([-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], gripper_offset=0.12)
    with pytest.raises(ConfigError) as exc:
        plan_line(avp.State.hover([0.3, 0.05, 1.05]), line, CFG)
    assert exc.value.field == "state.position"
    with pytest.raises(ConfigError):
        plan_line(avp.State.hover([0.3, 0.0, 1.5]), line, with_ground(2.0))
    with pytest.raises(ConfigError):
        LineOptions(wedge_angle=math.pi)


@pytest.mark.parametrize("pitch", [20.0, 80.0])
def test_plane_perch_equivalent_keeps_the_line_clearance(pitch: float) -> None:
    """The adapter for the plane planner / Replanner: its certified plan also passes the line
    certificates (exact) and meets the line's contact conditions."""
    from avp.line_planner import line_checks, perch_equivalent

    line = horizontal_line(z=2.5, incline_deg=8.0, pitch=math.radians(pitch))
    state = avp.State.hover([0.5, 0.2, 2.4])
    target, cfg = perch_equivalent(state, line, CFG)
    result = avp.plan_detailed(state, target, cfg)
    assert result.ok, result.log
    tr = result.trajectory
    contact = line.contact(state.position, state.yaw)
    checks = line_checks(tr, "perch", line, contact, LineOptions(), contact_at_end=True, start_root=None)
    certs = run_checks(checks, {"perch": tr.knots})
    assert all(c.ok for c in certs), [str(c) for c in certs if not c.ok]
    b3 = tr.attitude(tr.tf)[:, 2]
    assert math.degrees(math.acos(min(1.0, float(b3 @ contact.n)))) < 0.5
    assert np.linalg.norm(tr(tr.tf) - line.gripper_offset * b3 - contact.grasp_point(0.5)) < 1e-3
    replanner = avp.Replanner(target, cfg)
    step = replanner.step(0.0, state)
    assert step.trajectory is not None


def test_line_perch_example_runs(tmp_path: object) -> None:
    import subprocess
    import sys
    from pathlib import Path

    example = Path(__file__).resolve().parent.parent / "examples" / "line_perch.py"
    proc = subprocess.run([sys.executable, str(example)], capture_output=True, text=True, timeout=120, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("status: SOLVED")
    assert "bounds certified" in proc.stdout


def test_capsule_certificate_clears_the_extension_but_not_the_segment() -> None:
    """A path crossing the infinite line beyond the segment's end: the line test fails, the
    segment (capsule) test proves it; a path crossing the segment itself is never proven."""
    from avp.line_certify import capsule_certificate

    A, B, r = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 1.0]), 0.1
    coeffs = np.zeros((1, 4, 2))
    coeffs[0, :3, 0] = [1.5, -1.0, 1.0]  # passes the extension at x = 1.5 (0.5 m past B)
    coeffs[0, 1, 1] = 2.0
    beyond = Trajectory(coeffs, [0.0, 1.0])
    pos = position_polys(beyond, 0)
    F, scale = clearance_poly(pos, A, B, r)
    (line_cert,) = run_checks([PolyCheck("c", "t", 0, F, scale=scale)], {"t": beyond.knots})
    assert line_cert.verdict is Certificate.VIOLATED
    cap = capsule_certificate(pos, A, B, r, "c", "t", 0, beyond.knots)
    assert cap.verdict is Certificate.WITHIN
    seg = LineTarget.segment(A, B)
    assert min(seg.distance(p) for p in beyond(np.linspace(0, 1, 2001))) > r
    through = coeffs.copy()
    through[0, 0, 0] = 0.5
    cross = Trajectory(through, [0.0, 1.0])
    cap2 = capsule_certificate(position_polys(cross, 0), A, B, r, "c", "t", 0, cross.knots)
    assert cap2.verdict is not Certificate.WITHIN


def test_hanging_below_a_catenary_is_certified() -> None:
    line = LineTarget.catenary([2.0, -5.0, 4.3], [2.0, 5.0, 4.3], sag=0.6, pieces=8, pitch=math.pi,
                               grasp_piece=4, grasp=0.5, gripper_offset=0.15)
    res = plan_line(avp.State.hover([0.0, 0.0, 2.0]), line, with_ground(0.8))
    assert res.ok, res.log
    for traj in (res.perch, res.recovery):
        assert sampled_distance(traj, line).min() >= 0.15 - 1e-6


def test_workspace_refinement_certifies_a_line_perch_past_a_sphere() -> None:
    """A sphere on the way to a line: without refinement rounds no duration is certified (the
    initial sampled rows let the plan clip it); with them, rows around the proven violation
    certify a plan, and a dense grid (not the certificate) keeps perch and recovery outside the
    sphere and off the line."""
    limits = VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81)
    line = LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=0.0, gripper_offset=0.15)
    start = avp.State.hover([0.0, 0.0, 2.5])
    sphere = avp.Sphere(center=(1.0, 0.0, 3.25), radius=0.3)
    ws = Workspace(ground_z=0.8, spheres=(sphere,))
    none = plan_line(start, line, PlannerConfig(limits=limits, workspace=replace(ws, refinement_rounds=0)))
    assert none.status is LineStatus.NOT_CERTIFIED
    assert any(c.name.startswith("workspace: sphere") for c in none.violations)
    res = plan_line(start, line, PlannerConfig(limits=limits, workspace=ws))
    assert res.status is LineStatus.SOLVED, res.log
    assert any("workspace refinement round" in entry for entry in res.log)
    for traj in (res.perch, res.recovery):
        p = traj(np.linspace(traj.t0, traj.tf, 20001))
        assert np.linalg.norm(p - np.asarray(sphere.center), axis=1).min() > sphere.radius
    assert sampled_distance(res.perch, line).min() >= line.gripper_offset - 1e-9


def test_a_line_perch_logs_the_pad_settings_it_does_not_use() -> None:
    """A configuration shared with pad perches: the settings a line perch does not use are named
    in its log when they differ from the defaults, and only then; they do not change the plan."""
    start = avp.State.hover([1.0, 0.0, 2.6])
    line = horizontal_line(pitch=math.radians(45))
    plain = plan_line(start, line, CFG, LineOptions(recovery=False))
    assert not any(entry.startswith("config:") for entry in plain.log)
    pad_cfg = replace(CFG, alpha_range=(5.0, 9.0), fov=avp.FovConfig(enabled=False), q=0.3,
                      workspace=Workspace(body_offset=0.1))
    res = plan_line(start, line, pad_cfg, LineOptions(recovery=False))
    notes = [entry for entry in res.log if entry.startswith("config:")]
    assert len(notes) == 1
    for name in ("alpha_range", "fov", "q", "workspace.body_offset"):
        assert name in notes[0]
    assert "contact_velocity" not in notes[0]
    assert np.array_equal(res.perch.coefficients, plain.perch.coefficients)


def test_an_unknown_line_setting_is_a_typed_error() -> None:
    """A misspelt keyword of ``LineTarget.segment`` / ``catenary`` names itself (it was a raw
    TypeError)."""
    for make in (lambda **kw: avp.LineTarget.segment([0, 0, 1], [1, 0, 1], **kw),
                 lambda **kw: avp.LineTarget.catenary([0, 0, 3], [10, 0, 3], 1.0, **kw)):
        with pytest.raises(avp.ConfigError) as exc:
            make(pitchh=1.0)
        assert exc.value.field == "line.pitchh" and "'pitch'" in str(exc.value)
        assert make(pitch=1.0).pitch == 1.0


@pytest.mark.parametrize("point", ["abc", None, [1.0, 2.0], [1.0, math.nan, 0.0]])
def test_closest_refuses_a_point_that_is_not_three_finite_numbers(point) -> None:
    """Found by fuzzing: a string raised NumPy's ValueError and ``None`` returned ``(0, inf)``."""
    line = avp.LineTarget.segment([3.0, -1.5, 2.5], [3.0, 1.5, 2.5])
    with pytest.raises(avp.ConfigError) as exc:
        line.closest(point)
    assert exc.value.field == "point"


def test_line_plans_carry_their_provenance_into_exports() -> None:
    """The status and certificates travel with each line spline, as with avp.plan's: an exported
    perch says whether it was certified. An uncertified one, returned for diagnostics, said
    nothing (``provenance`` None) and exported as a plain spline."""
    line = LineTarget.segment([2.0, -1.5, 3.7], [2.0, 1.5, 3.7], pitch=0.0, gripper_offset=0.15)
    good = plan_line(avp.State.hover([0.0, 0.0, 2.5]), line)
    assert good.ok and good.recovery is not None
    for traj, bounds, label in ((good.perch, good.bounds, "perch"), (good.recovery, good.recovery_bounds, "recovery")):
        assert traj is not None and traj.provenance is not None and bounds is not None
        assert traj.provenance.status == LineStatus.SOLVED.value
        assert traj.provenance.bounds_certified == bounds.certified
        assert traj.provenance.workspace_certified == all(c.ok for c in good.certificates if c.trajectory == label)
        back = Trajectory.from_json(traj.to_json())
        assert back.provenance == traj.provenance
    bad = plan_line(avp.State.hover([2.0, 0.0, 2.5]), line)  # under the line: not certified
    assert bad.status is LineStatus.NOT_CERTIFIED and bad.perch is not None and bad.perch.provenance is not None
    assert bad.perch.provenance.status == LineStatus.NOT_CERTIFIED.value
    assert not bad.perch.provenance.workspace_certified  # its clearance fails (the wire)
    assert "NOT certified" in str(Trajectory.from_json(bad.perch.to_json()).provenance)
