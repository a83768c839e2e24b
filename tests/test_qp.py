"""The perching QP (avp.qp): the reduced and the textbook forms agree, and the elimination cache (a
factorisation depends on the equality matrix and the cost only, so QPs that differ in their
right-hand side share it, and a cached answer is exactly the uncached one)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scenarios import standard

import avp
import avp.qp.assemble as assemble
import avp.solve
from avp.qp.assemble import build_perching_qp
from avp.qp.cost import cost_matrix, gram
from avp.qp.layout import layout_for
from avp.qp.perching import _end_rows


def _qp(start, T, incline=30.0):
    target = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.5]), math.radians(incline))
    return build_perching_qp(avp.State.hover(np.asarray(start, float)), target, avp.PlannerConfig(), np.asarray(T))


def test_right_hand_side_changes_reuse_the_factorisation_exactly() -> None:
    T = [0.9, 0.8, 0.7]
    a, b = _qp([-3.0, 0.0, 2.5], T), _qp([-2.0, 0.4, 2.0], T)
    Aa, ba = a.stacked_equalities()
    Ab, bb = b.stacked_equalities()
    assert np.array_equal(Aa, Ab) and not np.array_equal(ba, bb)  # same pattern, new values
    assemble._FACTORS.clear()
    Za, cpa, Ha, _ = a.elimination
    Zb, cpb, Hb, gb = b.elimination
    assert Za is Zb and Ha is Hb and assemble._cached_factors() == 1  # one factorisation, shared
    for A, rhs, cp in ((Aa, ba, cpa), (Ab, bb, cpb)):
        assert np.max(np.abs(A @ cp - rhs)) < 1e-9 * max(1.0, np.max(np.abs(rhs)))
    # the cached answer is bit for bit the one computed from scratch
    assemble._FACTORS.clear()
    Z2, cp2, H2, g2 = _qp([-2.0, 0.4, 2.0], T).elimination
    assert np.array_equal(Z2, Zb) and np.array_equal(cp2, cpb) and np.array_equal(H2, Hb) and np.array_equal(g2, gb)
    # other durations: another factorisation
    assert _qp([-2.0, 0.4, 2.0], [0.9, 0.8, 0.75]).elimination[0] is not Zb
    assert assemble._cached_factors() == 2


@settings(max_examples=40, deadline=None)
@given(total=st.floats(0.3, 9.0), scale=st.floats(0.2, 5.0), incline=st.floats(0.0, 170.0),
       heading=st.floats(-math.pi, math.pi), tilt=st.floats(0.0, 0.2),
       drag=st.one_of(st.just(0.0), st.floats(0.05, 0.8)))
def test_equal_splits_and_any_pad_frame_share_one_exact_factorisation(total, scale, incline, heading, tilt,
                                                                      drag) -> None:
    """Every replan splits the time left equally and re-estimates the pad's frame. The equality
    matrix is then the same bits for any total time and any frame (rows scaled by one segment's
    duration exactly; the whole contact velocity as world rows ``v = R_WS v_S``; a rotor drag's
    ``d v(t_f)`` on the right-hand side of (12)), so the cached factorisation is an exact hit, and
    its splines still meet ``v_S`` in the new frame and, with drag, (12) on ``a + d v``."""
    base_config = avp.PlannerConfig(fov=avp.FovConfig(enabled=False))
    config = dataclasses.replace(base_config, limits=dataclasses.replace(base_config.limits, rotor_drag=drag))
    state = avp.State.hover(np.array([-2.5, 0.3, 2.2]))
    base = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.5]), math.radians(30.0))
    n = np.array([math.sin(math.radians(incline)) * math.cos(heading), math.sin(math.radians(incline)) *
                  math.sin(heading), math.cos(math.radians(incline))])
    other = avp.PerchTarget.from_normal(np.array([0.2, -0.1, 1.4]), n + tilt * np.array([0.3, -0.2, 0.1]))
    a = build_perching_qp(state, base, config, np.full(3, total / 3))
    b = build_perching_qp(state, other, config, np.full(3, scale * total / 3))
    assert np.array_equal(a.stacked_equalities()[0], b.stacked_equalities()[0])
    # one read-only object, so the factorisation is found by identity, not by its entries
    assert a.stacked_equalities()[0] is b.stacked_equalities()[0]
    assemble._FACTORS.clear()
    assert a.elimination[0] is b.elimination[0] and assemble._cached_factors() == 1
    A, rhs = b.stacked_equalities()
    _, c_p, _, _ = b.elimination
    assert np.max(np.abs(A @ c_p - rhs)) < 1e-9 * max(1.0, np.max(np.abs(rhs)))
    traj = b.trajectory(c_p, config.g)  # any point of the equalities' affine set meets them
    v_S = other.R_WS.T @ traj.derivatives(traj.tf)[1, :3]
    want = list(config.contact_velocity.components(other.incline))
    np.testing.assert_allclose(v_S, want, atol=1e-9 * max(1.0, float(np.max(np.abs(want)))))
    end = traj.derivatives(traj.tf)
    thrust = end[2, :3] + drag * end[1, :3]  # (12): a + d v = alpha s3 - g e3
    c0 = config.contact_alpha(other.incline) * other.s3 - config.g * np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(thrust, c0, atol=1e-9 * max(1.0, float(np.max(np.abs(c0)))))


def test_time_scaled_durations_reuse_the_factorisation_to_rounding() -> None:
    """Scaling every duration (the time search) changes the normalised A and P by rounding only:
    the factorisation is reused, the equalities of the new QP still hold, and the plan equals the
    one computed from scratch to rounding."""
    config = avp.PlannerConfig(fov=avp.FovConfig(enabled=False))
    state = avp.State.hover(np.array([-2.5, 0.3, 2.2]))
    target = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.5]), math.radians(60.0))
    T = np.array([0.7, 0.55, 0.4])
    assemble._FACTORS.clear()
    base = build_perching_qp(state, target, config, T)
    scaled = build_perching_qp(state, target, config, 1.15 * T)
    A0, A1 = base.stacked_equalities()[0], scaled.stacked_equalities()[0]
    assert not np.array_equal(A0, A1) and np.max(np.abs(A0 - A1)) <= assemble.REUSE_TOL * np.max(np.abs(A0))
    assert base.elimination[0] is scaled.elimination[0] and assemble._cached_factors() == 1
    Z, c_p, _, _ = scaled.elimination
    A1, b1 = scaled.stacked_equalities()
    assert np.max(np.abs(A1 @ Z)) < 1e-12 * np.max(np.abs(A1))
    assert np.max(np.abs(A1 @ c_p - b1)) < 1e-12 * max(1.0, np.max(np.abs(b1)))
    reused = avp.solve.solve_perching_qp(scaled, config)
    assemble._FACTORS.clear()
    fresh = avp.solve.solve_perching_qp(build_perching_qp(state, target, config, 1.15 * T), config)
    assert reused.ok and fresh.ok
    np.testing.assert_allclose(reused.c_hat, fresh.c_hat, rtol=0, atol=1e-9 * np.max(np.abs(fresh.c_hat)))


def test_cache_is_bounded(monkeypatch) -> None:
    monkeypatch.setattr(assemble, "ELIMINATION_CACHE_SIZE", 4)
    assemble._FACTORS.clear()
    for k in range(assemble.ELIMINATION_CACHE_SIZE + 5):
        assert _qp([-3.0, 0.0, 2.5], [0.9, 0.8, 0.7 + 1e-3 * k]).elimination[0].shape[0] > 0
    assert assemble._cached_factors() == assemble.ELIMINATION_CACHE_SIZE


def test_evicted_stacks_take_their_fingerprints_with_them(monkeypatch) -> None:
    """The stacked equality matrices are cached by their blocks' identities up to
    ELIMINATION_CACHE_SIZE; an evicted one leaves neither the stack cache nor the fingerprints,
    and a QP built again after eviction gets an equal matrix (a new object) and the same
    elimination."""
    monkeypatch.setattr(assemble, "ELIMINATION_CACHE_SIZE", 3)
    assemble._STACKS.clear()
    assemble._PRINTS.clear()
    config = avp.PlannerConfig(fov=avp.FovConfig(enabled=False))
    state = avp.State.hover(np.array([-2.5, 0.3, 2.2]))
    target = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.5]), math.radians(30.0))
    stacks = []
    for k in range(12):
        qp = build_perching_qp(state, target, config, np.array([0.5 + 0.1 * k, 0.6, 0.7]))  # unequal: new blocks
        stacks.append(qp.stacked_equalities()[0])
        assert len(assemble._STACKS) <= 3
    cached = {id(A) for _, A in assemble._STACKS.values()}
    for A in stacks:
        entry = assemble._PRINTS.get(id(A))
        assert (entry is not None and entry[0] is A) == (id(A) in cached)
    again = build_perching_qp(state, target, config, np.array([0.5, 0.6, 0.7]))
    A0 = again.stacked_equalities()[0]
    assert A0 is not stacks[0] and A0.tobytes() == stacks[0].tobytes()
    assert again.elimination[1].tobytes() == build_perching_qp(state, target, config, np.array([0.5, 0.6, 0.7])).elimination[1].tobytes()


def test_cost_matrix_matches_its_definition_and_is_read_only() -> None:
    layout = layout_for(3, 7)
    T = np.array([0.6, 1.1, 0.8])
    P = cost_matrix(layout, T, 4, 2)
    assert not P.flags.writeable
    assert P is cost_matrix(layout, T.copy(), 4, 2)  # cached per value
    # block (axis, segment) = (T_total / T_i)^(2j - 1) G_j, normalised to a unit largest diagonal
    ref = np.zeros_like(P)
    n = layout.n_coeffs
    for axis in range(4):
        j = 2 if axis == 3 else 4
        for seg in range(3):
            s = layout.start(axis, seg)
            ref[s:s + n, s:s + n] = (T.sum() / T[seg]) ** (2 * j - 1) * gram(7, j)
    np.testing.assert_allclose(P, ref / np.max(np.diag(ref)), rtol=1e-14, atol=0)


def test_reduced_and_full_forms_agree() -> None:
    sc = standard(60, 3.5)
    red = avp.plan(sc.state, sc.target, avp.PlannerConfig(solver="proxqp"))
    full = avp.plan(sc.state, sc.target, avp.PlannerConfig(solver="proxqp", qp_form=avp.QpForm.FULL))
    t = red.sample(0.01)
    assert np.max(np.abs(red(t) - full(t))) < 1e-4


def test_incremental_reduction_equals_a_fresh_one() -> None:
    """A copy with FoV blocks reuses its parent's stacked and reduced rows: the result equals
    stacking and reducing the same blocks from scratch."""
    import numpy as np
    from scenarios import standard

    import avp
    from avp import perception
    from avp.qp.assemble import PerchingQp, build_perching_qp
    from avp.solve import solve_perching_qp
    from avp.timing import initial_durations

    sc = standard(60, 3.5)
    cfg = avp.PlannerConfig()
    T = initial_durations(sc.state, sc.target, cfg)
    base = build_perching_qp(sc.state, sc.target, cfg, T)
    out = solve_perching_qp(base, cfg)  # computes the parent's stacked rows and reduction
    lin = perception.linearise_on(base, base.trajectory(out.c_hat, cfg.g), sc.target, cfg)
    child = base.with_inequalities(*lin.blocks)
    fresh = PerchingQp(layout=base.layout, durations=base.durations, t0=base.t0, P=base.P,
                       equalities=base.equalities, inequalities=child.inequalities)
    a, b = child.reduce(), fresh.reduce()
    for name in ("H", "g", "G", "lower", "upper", "Z", "c_p"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-13, atol=1e-13, err_msg=name)
    for x, y in zip(child.stacked_inequalities(), fresh.stacked_inequalities(), strict=True):
        assert np.array_equal(x, y)
    # the least-distance form too: the parent's transformed rows (computed by the solve) plus
    # the new rows', the same as a fresh QP's to rounding, with the parent's factor
    assert "_least_distance" in base.__dict__
    la, lb = child.least_distance(), fresh.least_distance()
    assert la is not None and lb is not None and la.R is base.least_distance().R
    np.testing.assert_allclose(la.M, lb.M, rtol=1e-12, atol=1e-12 * float(np.abs(lb.M).max()))
    np.testing.assert_allclose(la.v, lb.v, rtol=1e-12, atol=1e-12 * float(np.abs(lb.v).max()))
    parent = base.least_distance()
    assert la.M[:parent.M.shape[0]].tobytes() == parent.M.tobytes() and la.v is parent.v
    same = base.with_inequalities()  # no new rows: the parent's rows
    assert same.least_distance().M is base.least_distance().M
    # the planner's order: a second child stacked before it is reduced gets all three from the
    # same kernel call (append_rows), whichever is asked first; the same reduction, bit for bit
    second = base.with_inequalities(*lin.blocks)
    second.stacked_inequalities()
    c = second.reduce()
    assert "_stacked_inequalities" in second.__dict__
    for name in ("G", "lower", "upper"):
        assert getattr(c, name).tobytes() == getattr(a, name).tobytes(), name
    # a child whose factor is another one than its parent's does not take the parent's rows: with
    # 2 R, every row and the linear term are halved
    third = base.with_inequalities(*lin.blocks)
    third.__dict__["_cholesky"] = 2.0 * base.least_distance().R
    lt = third.least_distance()
    assert lt is not None
    np.testing.assert_allclose(lt.M, la.M / 2, rtol=1e-12, atol=1e-12 * float(np.abs(la.M).max()))
    np.testing.assert_allclose(lt.v, la.v / 2, rtol=1e-12, atol=1e-12 * float(np.abs(la.v).max()))
    # nor one whose linear term is another object (another right-hand side): its own v
    fourth = base.with_inequalities(*lin.blocks)
    fourth.__dict__["_reduced"] = dataclasses.replace(child.reduce(), g=2.0 * child.reduce().g)
    lf = fourth.least_distance()
    assert lf is not None and lf.v is not parent.v
    np.testing.assert_allclose(lf.v, 2 * la.v, rtol=1e-12, atol=1e-12 * float(np.abs(la.v).max()))


@settings(max_examples=200, deadline=None)
@given(
    durations=st.lists(st.floats(0.05, 3.0), min_size=3, max_size=3),
    fractions=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30),
    order=st.integers(0, 4), order2=st.integers(0, 4), weight=st.floats(-2.0, 2.0),
    at_end=st.booleans(),
)
def test_point_rows_plus_is_the_sum_of_two_row_sets(durations, fractions, order, order2, weight, at_end) -> None:
    """``point_rows(..., plus=(r2, w))`` (the band's ``a + d v`` rows in one pass) has exactly the
    values of the ``order`` rows plus ``w`` times the ``r2`` rows, at any times (one time at the
    plan's end takes the endpoint basis, many times several segments)."""
    from avp.qp.rows import point_rows

    layout = layout_for(3, 7)
    knots = np.concatenate([[0.0], np.cumsum(durations)])
    times = knots[-1] if at_end else knots[-1] * np.asarray(fractions)
    combined = point_rows(layout, knots, order, times, plus=(order2, weight))
    summed = point_rows(layout, knots, order, times) + weight * point_rows(layout, knots, order2, times)
    assert combined.tobytes() == summed.tobytes()  # bit for bit (array_equal takes -0.0 for 0.0)


@settings(max_examples=30, deadline=None)
@given(drag=st.sampled_from([0.0, 0.05, 0.4]), incline=st.floats(0.0, 170.0), heading=st.floats(-math.pi, math.pi),
       total=st.floats(0.5, 6.0))
def test_the_shared_terminal_rows_meet_the_contact_conditions(drag, incline, heading, total) -> None:
    """The terminal matrix shared by every pad (cached, read-only: position, acceleration, the
    whole contact velocity as world rows, yaw; the drag's ``d v`` is on the right-hand side) is
    the same object for two pads and any drag, and any spline of the equalities' affine set ends
    at the pad with ``a + d v = alpha s3 - g e3`` (12) and ``v = R_WS v_S``, evaluated on the
    trajectory itself."""
    config = avp.PlannerConfig(fov=avp.FovConfig(enabled=False),
                               limits=avp.VehicleLimits(rotor_drag=drag))
    state = avp.State.hover(np.array([-2.5, 0.3, 2.2]))
    inc = math.radians(incline)
    a = avp.PerchTarget.from_incline(np.array([0.1, -0.2, 1.5]), inc, heading)
    b = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.0]), math.radians(45.0))
    T = np.full(3, total / 3)
    qa, qb = build_perching_qp(state, a, config, T), build_perching_qp(state, b, config, T)
    At = qa.equalities[2].matrix
    assert At is qb.equalities[2].matrix and not At.flags.writeable
    # bit for bit the rows one at a time (position, acceleration, velocity, yaw), as built before the cache
    P, V, A, Y = _end_rows(3, config.degree, 1.0)
    assert At.tobytes() == np.array([*P, *A, *V, Y]).tobytes()
    drag_free = dataclasses.replace(config, limits=avp.VehicleLimits(rotor_drag=0.0))
    assert build_perching_qp(state, a, drag_free, T).equalities[2].matrix is At
    _, c_p, _, _ = qa.elimination
    traj = qa.trajectory(c_p, config.g)
    d = traj.derivatives(traj.tf)  # (orders, 4): position, velocity, acceleration
    alpha = config.contact_alpha(a.incline)
    np.testing.assert_allclose(d[0, :3], a.point + config.workspace.body_offset * a.s3, atol=1e-9)
    np.testing.assert_allclose(d[2, :3] + drag * d[1, :3], alpha * a.s3 - config.g * np.array([0.0, 0.0, 1.0]), atol=1e-8)
    v_S = list(config.contact_velocity.components(a.incline))
    np.testing.assert_allclose(a.R_WS.T @ d[1, :3], v_S, atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(kind=st.sampled_from(["alpha_range", "slope free", "normal free", "lateral free", "alpha_range, slope free"]),
       drag=st.sampled_from([0.0, 0.3]),
       incline=st.floats(10.0, 170.0), heading=st.floats(-math.pi, math.pi), total=st.floats(0.8, 6.0),
       tilt=st.floats(0.01, 0.3))
def test_rows_in_the_pads_frame_are_eliminated_inside_the_cached_null_space(kind, drag, incline, heading, total,
                                                                            tilt) -> None:
    """With ``alpha_range`` or a partly free contact velocity some terminal rows lie along the
    pad's frame, which every replan re-estimates. The other equalities keep one cached
    factorisation for every pad; the pad's rows are eliminated inside its null space. Judged by
    an independent solve: the equality-constrained minimiser of the cost from the KKT system of
    the whole ``A``, and the contact conditions on the spline itself."""
    base = avp.PlannerConfig(fov=avp.FovConfig(enabled=False), limits=avp.VehicleLimits(rotor_drag=drag))
    config = base
    if kind.startswith("alpha_range"):
        config = dataclasses.replace(config, alpha_range=(6.0, 14.0))
    for component in ("slope", "normal", "lateral"):
        if f"{component} free" in kind:
            config = dataclasses.replace(config, contact_velocity=dataclasses.replace(
                config.contact_velocity, **{component: None}))
    state = avp.State.hover(np.array([-2.5, 0.3, 2.2]))
    inc = math.radians(incline)
    a = avp.PerchTarget.from_incline(np.array([0.1, -0.2, 1.5]), inc, heading)
    n = a.s3 + tilt * np.array([0.3, -0.5, 0.2])
    b = avp.PerchTarget.from_normal(np.array([0.0, 0.1, 1.4]), n)
    T = np.full(3, total / 3)
    qa, qb = build_perching_qp(state, a, config, T), build_perching_qp(state, b, config, T)
    assert [blk.name for blk in qa.equalities][-1] == "terminal, in the pad's frame"
    assert qa.equalities[2].matrix is qb.equalities[2].matrix  # the fixed terminal rows
    assemble._FACTORS.clear()
    assemble._WITHIN.clear()
    Za, _, _, _ = qa.elimination
    Z, c_p, H, g = qb.elimination
    assert assemble._cached_factors() == 1  # the fixed rows: one factorisation for both pads
    A, rhs = qb.stacked_equalities()
    scale = max(1.0, float(np.max(np.abs(rhs))))
    assert np.max(np.abs(A @ c_p - rhs)) < 1e-9 * scale
    assert np.max(np.abs(Z.T @ Z - np.eye(Z.shape[1]))) < 1e-12
    assert np.max(np.abs(A @ Z)) < 1e-10 * max(1.0, float(np.max(np.abs(A))))
    assert Z.shape == Za.shape  # the same number of free directions for any pad
    # the minimiser of the cost on the equalities alone: from the reduced QP; from the KKT system
    # of the whole A solved directly (no elimination, no cache: ill-conditioned, up to 1e10, so
    # compared by its cost, which the unique minimiser cannot exceed); and from one QR of the
    # whole A (the elimination without the pad's rows split off)
    def cost(c: np.ndarray) -> float:
        return 0.5 * float(c @ qb.P @ c)

    c_red = c_p + Z @ np.linalg.solve(H, -g)
    m, nv = A.shape
    K = np.block([[qb.P, A.T], [A, np.zeros((m, m))]])
    c_kkt = np.linalg.lstsq(K, np.concatenate([np.zeros(nv), rhs]), rcond=None)[0][:nv]
    assert np.max(np.abs(A @ c_kkt - rhs)) < 1e-8 * scale
    assert cost(c_red) <= cost(c_kkt) + 1e-12 * max(1.0, abs(cost(c_kkt)))
    f = assemble._factor(np.array(A), qb.P)
    c_one = assemble._particular(f, rhs)
    c_one = c_one + f.Z @ np.linalg.solve(f.H, -f.scale * (f.PZ.T @ c_one))
    np.testing.assert_allclose(c_red, c_one, rtol=0, atol=1e-8 * max(1.0, float(np.max(np.abs(c_one)))))
    # the contact conditions on the spline of the particular solution
    end = qb.trajectory(c_p, config.g).derivatives(float(qb.knots_rel[-1]))
    np.testing.assert_allclose(end[0, :3], b.point + config.workspace.body_offset * b.s3, atol=1e-9)
    thrust = end[2, :3] + drag * end[1, :3] + config.g * np.array([0.0, 0.0, 1.0])
    if kind.startswith("alpha_range"):  # (12) with alpha free: along s3
        assert abs(float(thrust @ b.s1)) < 1e-8 and abs(float(thrust @ b.s2)) < 1e-8
    else:
        np.testing.assert_allclose(thrust, config.contact_alpha(b.incline) * b.s3, atol=1e-8)
    given = config.contact_velocity.components(b.incline)
    v_S = b.R_WS.T @ end[1, :3]
    for got, want in zip(v_S, given, strict=True):
        if want is not None:
            assert abs(got - want) < 1e-9 * max(1.0, abs(want))
    # the same pad again: its second stage is a cache hit, and both equal a fresh one bit for bit
    entries = len(assemble._WITHIN)
    hit = build_perching_qp(state, b, config, T).elimination
    assert len(assemble._WITHIN) == entries and hit[0] is Z
    assemble._WITHIN.clear()
    fresh = build_perching_qp(state, b, config, T).elimination
    for x, y, z in zip(hit, fresh, (Z, c_p, H, g), strict=True):
        assert x.tobytes() == y.tobytes() == z.tobytes()


def test_a_second_stage_without_free_directions_checks_the_rows_it_cannot_move() -> None:
    """The cached rows leave no free direction (``Z0`` has no column): the pad's rows either hold
    at the particular solution already (an empty null space is returned) or are a typed
    infeasibility, not a LAPACK error."""
    rng = np.random.default_rng(3)
    n = 6
    Z0, c0, G0, P = np.zeros((n, 0)), rng.normal(size=n), np.zeros((0, 0)), np.eye(n)
    A_t = rng.normal(size=(2, n))
    Z, c_p, H, g = assemble.eliminate_within(Z0, c0, G0, P, A_t, A_t @ c0)
    assert Z.shape == (n, 0) and H.shape == (0, 0) and g.shape == (0,)
    assert c_p.tobytes() == c0.tobytes()
    with pytest.raises(avp.InfeasibleError, match="inconsistent"):
        assemble.eliminate_within(Z0, c0, G0, P, A_t, A_t @ c0 + 1.0)


@pytest.mark.parametrize("solver", ["daqp", "osqp"])
def test_the_full_form_is_refused_with_the_back_ends_that_miss_its_optimum(solver):
    """The full form's Hessian is singular; DAQP and OSQP returned feasible plans far from its
    optimum there, reported as SOLVED (figures at Backend.full_form)."""
    with pytest.raises(avp.ConfigError, match="config.qp_form"):
        avp.PlannerConfig(solver=solver, qp_form=avp.QpForm.FULL)
    avp.PlannerConfig(solver=solver)  # the reduced form stays


def test_proxqp_meets_the_reduced_optimum_in_the_full_form_where_daqp_did_not():
    """ProxQP stays allowed with the full form: on the case where DAQP missed the optimum (12
    segments of degree 9) it meets the reduced form's snap cost (Backend.full_form is True)."""
    wall = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], np.pi / 2)
    start = avp.State.hover([0.0, 0.0, 1.5])

    def snap_cost(**kw):
        cfg = avp.PlannerConfig(n_segments=12, degree=9, **kw)
        cfg = dataclasses.replace(cfg, fov=dataclasses.replace(cfg.fov, enabled=False))
        tr = avp.plan(start, wall, cfg)
        t = tr.sample(1e-3)
        return float(np.sum(tr(t, 4) ** 2) * 1e-3)

    reduced = snap_cost()
    assert avp.solve.backend("proxqp").full_form
    assert snap_cost(solver="proxqp", qp_form=avp.QpForm.FULL) == pytest.approx(reduced, rel=1e-3)


@settings(max_examples=100, deadline=None)
@given(n=st.integers(1, 12), seed=st.integers(0, 2**32 - 1), shift=st.floats(1e-3, 10.0), m=st.integers(0, 8))
def test_the_least_distance_form_is_the_reduced_qp_whitened(n, seed, shift, m) -> None:
    """``cholesky_factor(H)`` is the upper triangular ``R`` with ``R^T R = H`` (read-only;
    ``None`` for a matrix with no factor), and the least-distance form's rows and linear term are
    ``G R^-1`` and ``R^-T g`` (checked against NumPy's general solver), with ``reduced(R z) =
    z``: the same QP in ``u = R z``."""
    import numpy as np

    from avp.qp.assemble import LeastDistanceQp, _rows_over, _solve_upper, cholesky_factor

    rng = np.random.default_rng(seed)
    B = rng.standard_normal((n, n))
    H = B @ B.T + shift * np.eye(n)
    R = cholesky_factor(H)
    assert R is not None and not R.flags.writeable
    assert np.array_equal(R, np.triu(R))
    np.testing.assert_allclose(R.T @ R, H, rtol=1e-12, atol=1e-12 * np.abs(H).max())
    G, g, z = rng.standard_normal((m, n)), rng.standard_normal(n), rng.standard_normal(n)
    ldp = LeastDistanceQp(R, _rows_over(R, G), _solve_upper(R, g, transposed=True))
    assert ldp.M.shape == (m, n) and ldp.M.flags.c_contiguous and ldp.M.flags.writeable  # DAQP's buffers
    scale = np.linalg.cond(R)
    np.testing.assert_allclose(ldp.M, np.linalg.solve(R.T, G.T).T, atol=1e-12 * scale * max(1.0, float(np.abs(G).max(initial=0.0))))
    np.testing.assert_allclose(ldp.v, np.linalg.solve(R.T, g), atol=1e-12 * scale * max(1.0, np.abs(g).max()))
    np.testing.assert_allclose(ldp.reduced(R @ z), z, atol=1e-12 * scale * max(1.0, np.abs(z).max()))
    assert cholesky_factor(-H) is None  # negative definite: no factor
    assert cholesky_factor(np.zeros((0, 0))) is None


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40), m=st.integers(0, 30), k0=st.integers(0, 6),
       sizes=st.lists(st.integers(0, 12), min_size=0, max_size=4), density=st.sampled_from([0.1, 0.5, 1.0]),
       factor=st.sampled_from(["cholesky", "none", "singular"]), ldp=st.booleans())
def test_appended_rows_equal_numpy_and_blas_reductions(seed, n, m, k0, sizes, density, factor, ldp) -> None:
    """``_avp_rust.append_rows`` (the kernel behind ``PerchingQp.with_inequalities``' reduction)
    against NumPy and BLAS: the stacked rows and bounds as given (bit for bit), ``G Z`` and the
    bounds minus ``G c_p`` to rounding (infinite bounds stay infinite), and the least-distance
    rows ``M`` with ``M R = G Z`` to rounding (SciPy's ``trsm``), or ``None`` without a factor or
    parent rows, or when the factor is singular; the parent's rows come first, unchanged."""
    import scipy.linalg

    rng = np.random.default_rng(seed)
    Z, c_p = rng.normal(size=(n, m)), rng.normal(size=n)
    if seed % 2:
        Z = np.asfortranarray(Z)  # any layout is read by its values (the planner's Z is Fortran-ordered)
    A = rng.normal(size=(m, m))
    R = np.linalg.cholesky(A @ A.T + m * np.eye(m)).T  # upper, well conditioned; Fortran-ordered, as the planner's
    singular = factor == "singular" and m > 0  # no variables: no pivot to zero
    if singular:
        R[m // 2, m // 2] = 0.0
    blocks = []
    for size in sizes:
        G = rng.normal(size=(size, n)) * (rng.uniform(size=(size, n)) < density)
        lo = np.where(rng.uniform(size=size) < 0.3, -np.inf, rng.normal(size=size) - 1.0)
        hi = np.where(rng.uniform(size=size) < 0.3, np.inf, rng.normal(size=size) + 1.0)
        blocks.append((np.ascontiguousarray(G), lo, hi))
    G0 = rng.normal(size=(k0, n))
    Gz0, lo0, hi0 = rng.normal(size=(k0, m)), -np.ones(k0), np.ones(k0)
    M0 = rng.normal(size=(k0, m)) if ldp else None
    out = avp._avp_rust.append_rows(G0, lo0, hi0, Gz0, lo0 - 1.0, hi0 + 1.0, M0, blocks, Z, c_p,
                                    None if factor == "none" else R)
    G, lo, hi, Gz, lo_z, hi_z, M = out
    Gn = np.concatenate([G0] + [b[0] for b in blocks]) if blocks else G0
    new = Gn[k0:]
    assert np.array_equal(G, Gn) and G.shape == (Gn.shape[0], n)
    assert np.array_equal(lo, np.concatenate([lo0] + [b[1] for b in blocks]))
    assert np.array_equal(hi, np.concatenate([hi0] + [b[2] for b in blocks]))
    assert np.array_equal(Gz[:k0], Gz0) and np.array_equal(lo_z[:k0], lo0 - 1.0) and np.array_equal(hi_z[:k0], hi0 + 1.0)
    scale = np.abs(new) @ np.abs(Z) + 1.0  # the size of the terms summed in each entry
    assert np.all(np.abs(Gz[k0:] - new @ Z) <= 1e-13 * scale)
    gc, gc_scale = new @ c_p, np.abs(new) @ np.abs(c_p) + 1.0
    for got, bound in ((lo_z[k0:], lo[k0:]), (hi_z[k0:], hi[k0:])):
        fin = np.isfinite(bound)
        assert np.array_equal(got[~fin], bound[~fin])
        assert np.all(np.abs(got[fin] - (bound[fin] - gc[fin])) <= 1e-13 * (gc_scale[fin] + np.abs(bound[fin])))
    if factor == "none" or not ldp or (singular and new.shape[0]):
        assert M is None  # no factor or parent rows; or a zero pivot: 0/0 or x/0 in every new row
        return
    assert M is not None and M.shape == (G.shape[0], m) and M.flags.c_contiguous and M.flags.writeable
    assert np.array_equal(M[:k0], M0)
    want = scipy.linalg.solve_triangular(R, Gz[k0:].T, trans="T", lower=False).T  # M R = G Z
    assert np.all(np.abs(M[k0:] - want) <= 1e-12 * (np.abs(want) + np.abs(Gz[k0:]).max(initial=0.0) + 1.0))


def test_append_rows_refuses_bad_shapes_naming_the_argument() -> None:
    """A block with the wrong number of columns or bounds, or parent rows of another width: a
    ``KernelError`` naming the argument."""
    n, m = 4, 3
    Z, c_p, R = np.ones((n, m)), np.ones(n), np.eye(m)
    e = np.zeros((0, n)), np.zeros(0), np.zeros(0), np.zeros((0, m)), np.zeros(0), np.zeros(0), np.zeros((0, m))
    good = (np.ones((2, n)), np.zeros(2), np.ones(2))
    assert avp._avp_rust.append_rows(*e, [good], Z, c_p, R)[6] is not None
    as_ints = avp._avp_rust.append_rows(*e, [(np.ones((2, n), dtype=int), np.zeros(2, dtype=int), np.ones(2, dtype=int))],
                                        Z, c_p, R)  # integer rows: read by their values
    for a, b in zip(as_ints, avp._avp_rust.append_rows(*e, [good], Z, c_p, R), strict=True):
        assert a.dtype == np.float64 and np.array_equal(a, b)
    for blocks, arg in (([(np.ones((2, n + 1)), np.zeros(2), np.ones(2))], "blocks.matrix"),
                        ([(np.ones((2, n)), np.zeros(3), np.ones(2))], "blocks.matrix"),
                        ([(np.ones((2, n)), np.zeros(2), np.ones(1))], "blocks.upper")):
        with pytest.raises(avp._avp_rust.KernelError) as info:
            avp._avp_rust.append_rows(*e, blocks, Z, c_p, R)
        assert info.value.arg == arg
    with pytest.raises(avp._avp_rust.KernelError) as info:  # parent rows of another width
        avp._avp_rust.append_rows(np.zeros((1, n + 1)), np.zeros(1), np.ones(1), np.zeros((1, m)), np.zeros(1),
                                  np.ones(1), np.zeros((1, m)), [good], Z, c_p, R)
    assert info.value.arg == "g"
    with pytest.raises(avp._avp_rust.KernelError) as info:  # a factor of another size
        avp._avp_rust.append_rows(*e, [good], Z, c_p, np.eye(m + 1))
    assert info.value.arg == "r"


def test_a_copy_of_a_qp_without_least_distance_form_reduces_its_new_rows_alone() -> None:
    """A parent solved by a one-sided back end in the reduced form (OSQP) has stacked and
    reduced rows but no least-distance form computed: a copy with more rows reduces only its new
    rows (views of its stacked rows when those come first), equal to a fresh QP's to rounding,
    and then gets the least-distance form of all its rows."""
    from avp import perception
    from avp.qp.assemble import PerchingQp
    from avp.solve import solve_perching_qp
    from avp.timing import initial_durations

    sc = standard(60, 3.5)
    cfg = avp.PlannerConfig(solver="osqp")
    T = initial_durations(sc.state, sc.target, cfg)
    base = build_perching_qp(sc.state, sc.target, cfg, T)
    out = solve_perching_qp(base, cfg)
    assert "_reduced" in base.__dict__ and "_least_distance" not in base.__dict__
    lin = perception.linearise_on(base, base.trajectory(out.c_hat, cfg.g), sc.target, cfg)
    for stacked_first in (True, False):
        child = base.with_inequalities(*lin.blocks)
        if stacked_first:
            child.stacked_inequalities()
        a = child.reduce()
        assert "_least_distance" not in child.__dict__  # the old path: nothing filled ahead
        fresh = PerchingQp(layout=base.layout, durations=base.durations, t0=base.t0, P=base.P,
                           equalities=base.equalities, inequalities=child.inequalities)
        b = fresh.reduce()
        k = base.reduce().G.shape[0]
        assert a.G[:k].tobytes() == base.reduce().G.tobytes()
        for name in ("G", "lower", "upper"):
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-13, atol=1e-13, err_msg=name)
        la, lb = child.least_distance(), fresh.least_distance()
        assert la is not None and lb is not None
        np.testing.assert_allclose(la.M, lb.M, rtol=1e-12, atol=1e-12 * float(np.abs(lb.M).max()))


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_seg=st.integers(1, 5), degree=st.integers(1, 9),
       magnitude=st.sampled_from([1.0, 1e100, 1e300]), order=st.sampled_from(["C", "F", "int"]))
def test_physical_coefficients_are_the_scaled_decision_vector_reordered(seed, n_seg, degree, magnitude,
                                                                         order) -> None:
    """``DecisionLayout.physical`` (one kernel call) gives NumPy's ``(c.reshape(4, S, N + 1) *
    T_i^-k).transpose(1, 0, 2)``, bit for bit, and says whether it is all finite (an overflowing
    product is not); ``to_physical`` and ``from_physical`` are inverse (to rounding); a decision
    vector of another length is refused by name."""
    rng = np.random.default_rng(seed)
    layout = layout_for(n_seg, degree)
    T = rng.uniform(1e-3, 3.0, n_seg)
    c = rng.normal(0.0, magnitude, layout.n_variables)
    scale = layout.physical_scale(T)
    shown = {"C": scale, "F": np.asfortranarray(scale), "int": scale}[order]
    given_c = np.round(c).astype(np.int64) if order == "int" and magnitude == 1.0 else c
    with np.errstate(over="ignore"):  # the products of 1e300 overflow: the kernel says so
        want = (given_c.astype(float).reshape(4, n_seg, degree + 1) * scale[None]).transpose(1, 0, 2)
    coeffs, finite = layout.physical(given_c, shown)
    assert coeffs.shape == (n_seg, 4, degree + 1) and coeffs.flags.c_contiguous
    assert coeffs.tobytes() == np.ascontiguousarray(want).tobytes()
    assert finite == bool(np.isfinite(want).all())
    if finite and magnitude == 1.0:
        np.testing.assert_allclose(layout.from_physical(coeffs, T), given_c, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(layout.to_physical(given_c, T), coeffs)
    with pytest.raises(avp.ConfigError, match="c_hat"):
        layout.physical(c[:-1], scale)
    with pytest.raises(avp.ConfigError, match="durations"):  # durations of another layout
        layout.to_physical(given_c, np.ones(n_seg + 1))
    np.testing.assert_array_equal(layout.to_physical(given_c.reshape(4, -1), T), coeffs)  # any shape, in order
