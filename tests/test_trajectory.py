"""Trajectory evaluation (Rust kernel vs NumPy oracle) and the flatness map (10), (11), (13), (22)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from oracles import eval_spline_reference
from scenarios import standard

import avp
from avp import _avp_rust, frames


@st.composite
def random_spline(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    S = draw(st.integers(1, 5))
    C = draw(st.integers(1, 11))
    A = draw(st.integers(1, 9))  # whole groups of four axes (one plan, two) and the rest
    coeffs = draw(hnp.arrays(float, (S, A, C), elements=st.floats(-100, 100)))
    durations = draw(hnp.arrays(float, (S,), elements=st.floats(0.05, 3.0)))
    knots = draw(st.floats(-5, 5)) + np.concatenate([[0.0], np.cumsum(durations)])
    return coeffs, knots


@given(random_spline(), st.integers(0, 6), st.lists(st.floats(0, 1), min_size=1, max_size=20))
def test_rust_eval_matches_numpy_reference(spline, order, fractions) -> None:
    coeffs, knots = spline
    times = knots[0] + np.array(fractions) * (knots[-1] - knots[0])
    got = _avp_rust.eval_spline(coeffs, knots, times, [order])[0]
    want = eval_spline_reference(coeffs, knots, times, order)
    scale = np.max(np.abs(coeffs)) * max(1.0, knots[-1] - knots[0]) ** coeffs.shape[2] * 10 ** order
    assert np.allclose(got, want, rtol=1e-10, atol=1e-12 * scale)


@given(random_spline(), st.integers(0, 6), st.lists(st.floats(-0.1, 1.1), min_size=1, max_size=20))
def test_rust_eval_is_one_horner_pass_per_axis_bit_for_bit(spline, order, fractions) -> None:
    """Each value is the Horner pass over the differentiated coefficients ``c_k k!/(k-order)!``
    (from the highest power, starting at 0.0) in Python floats, bit for bit: the kernel runs the
    axes' passes side by side without changing any one of them. Times outside the knots
    extrapolate the end segments."""
    import math

    coeffs, knots = spline
    times = knots[0] + np.array(fractions) * (knots[-1] - knots[0])
    got = _avp_rust.eval_spline(coeffs, knots, times, [order])[0]
    S, A, C = coeffs.shape
    for i, t in enumerate(times.tolist()):
        seg = min(max(int(np.searchsorted(knots, t, side="right")) - 1, 0), S - 1)
        tau = t - float(knots[seg])
        for a in range(A):
            acc = 0.0
            for k in range(C - 1, order - 1, -1):
                acc = acc * tau + float(coeffs[seg, a, k]) * float(math.perm(k, order))
            assert got[i, a] == acc or (math.isnan(acc) and math.isnan(got[i, a]))


@given(t0=st.one_of(st.just(0.0), st.floats(-1e4, 1e4), st.floats(1.0e9, 2.0e9)),
       durations=st.lists(st.floats(0.05, 3.0), min_size=1, max_size=4),
       fractions=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12))
def test_relative_times_in_floats_are_the_array_path_bit_for_bit(t0, durations, fractions) -> None:
    """``Trajectory._relative_floats`` (times in Python floats, the FoV linearisation's) gives
    ``_relative``'s values for the same times, bit for bit: at any clock value, at the knots and
    at ``tf`` itself (the spline's end exactly)."""
    rel = np.concatenate([[0.0], np.cumsum(durations)])
    traj = avp.Trajectory.from_relative_knots(np.zeros((len(durations), 4, 3)), rel, t0)
    times = [traj.t0 + f * (traj.tf - traj.t0) for f in fractions] + [traj.t0, traj.tf, *traj.knots.tolist()]
    times = [min(traj.tf, max(traj.t0, t)) for t in times]  # within the spline, as the caller clips them
    want = traj._relative(np.array(times))
    got = np.array(traj._relative_floats(times))
    assert got.tobytes() == want.tobytes()


def test_rust_kernel_rejects_bad_input_with_value_error() -> None:
    c = np.zeros((2, 4, 3))
    with pytest.raises(ValueError, match="knots"):
        _avp_rust.eval_spline(c, np.array([0.0, 1.0]), np.array([0.5]), [0])
    with pytest.raises(ValueError, match="strictly increasing"):
        _avp_rust.eval_spline(c, np.array([0.0, 1.0, 1.0]), np.array([0.5]), [0])
    with pytest.raises(ValueError, match="NaN"):
        _avp_rust.eval_spline(c, np.array([0.0, 1.0, 2.0]), np.array([np.nan]), [0])
    with pytest.raises(ValueError, match="order"):
        _avp_rust.eval_spline(c, np.array([0.0, 1.0, 2.0]), np.array([0.5]), [1000])


@pytest.fixture(scope="module")
def wall_plan() -> avp.Trajectory:
    sc = standard(90, 3.5)
    return avp.plan(sc.state, sc.target)


def test_shapes_and_domain(wall_plan: avp.Trajectory) -> None:
    tr = wall_plan
    assert tr(tr.t0).shape == (3,)
    assert tr(np.zeros((2, 5)) + tr.t0, 2).shape == (2, 5, 3)
    assert tr.yaw(np.array([tr.t0, tr.tf])).shape == (2,)
    assert tr.attitude(tr.sample(0.1)).shape == (tr.sample(0.1).size, 3, 3)
    assert tr.coefficients.shape == (3, 4, 8) and not tr.coefficients.flags.writeable
    with pytest.raises(avp.ConfigError, match="t"):
        tr(tr.tf + 0.1)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_times_with_nan_or_inf_anywhere_are_refused(wall_plan: avp.Trajectory, bad: float) -> None:
    tr = wall_plan
    for where in range(3):
        t = np.linspace(tr.t0, tr.tf, 3)
        t[where] = bad
        with pytest.raises(avp.ConfigError, match="NaN or inf"):
            tr.derivatives(t)


def test_times_are_checked_against_the_range_and_clipped_within_its_tolerance(wall_plan: avp.Trajectory) -> None:
    tr = wall_plan
    with pytest.raises(avp.ConfigError, match="must lie in"):
        tr(np.array([tr.t0, tr.t0 - 1e-6]))
    assert tr(np.zeros(0)).shape == (0, 3)
    # a hair outside the ends (rounding of a caller's grid) reads the end itself
    edge = np.array([tr.t0 - 1e-10, tr.tf + 1e-10])
    np.testing.assert_array_equal(tr(edge), tr(np.array([tr.t0, tr.tf])))
    # strided and 2-D inputs read the same values as contiguous ones
    grid = np.linspace(tr.t0, tr.tf, 12)
    np.testing.assert_array_equal(tr(grid[::3]), tr(np.ascontiguousarray(grid[::3])))
    np.testing.assert_array_equal(tr(grid.reshape(3, 4)[:, ::2]).reshape(-1, 3), tr(grid.reshape(3, 4)[:, ::2].ravel()))


def test_attitude_is_a_rotation_with_b3_along_thrust(wall_plan: avp.Trajectory) -> None:
    t = wall_plan.sample(0.01)
    R = wall_plan.attitude(t)
    assert np.allclose(np.einsum("nji,njk->nik", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    f = wall_plan(t, 2) + np.array([0, 0, frames.GRAVITY])
    assert np.allclose(R[:, :, 2], f / np.linalg.norm(f, axis=1, keepdims=True))
    assert np.allclose(wall_plan.thrust(t, mass=0.5), 0.5 * np.linalg.norm(f, axis=1))


def test_body_rates_match_finite_differences_of_attitude(wall_plan: avp.Trajectory) -> None:
    """hat(Omega) = R^T dR/dt (13), checked by central differences."""
    h = 1e-5
    t = np.linspace(wall_plan.t0 + 0.01, wall_plan.tf - 0.01, 40)
    R = wall_plan.attitude(t)
    dR = (wall_plan.attitude(t + h) - wall_plan.attitude(t - h)) / (2 * h)
    W = np.einsum("nji,njk->nik", R, dR)
    omega_fd = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    assert np.allclose(wall_plan.body_rates(t), omega_fd, atol=1e-5)


@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-5, 5), st.floats(-math.pi, math.pi), st.floats(-2, 2))
def test_body_rates_on_random_flat_states(ax, ay, az, yaw, yaw_rate) -> None:
    """The flatness map's body rates equal the finite-difference rates of R(a(t), psi(t)) for a
    locally linear a(t) and psi(t)."""
    a = np.array([ax, ay, az])
    j = np.array([0.7, -0.4, 1.1])
    h = 1e-6
    R0 = frames.attitude(a - h * j, yaw - h * yaw_rate)
    R1 = frames.attitude(a + h * j, yaw + h * yaw_rate)
    R = frames.attitude(a, yaw)
    W = R.T @ (R1 - R0) / (2 * h)
    omega_fd = np.array([W[2, 1], W[0, 2], W[1, 0]])
    assert np.allclose(frames.body_rates(a, j, yaw, yaw_rate), omega_fd, atol=1e-4)


def test_rotorpy_adapter(wall_plan: avp.Trajectory) -> None:
    out = wall_plan.to_rotorpy().update(0.3)
    assert set(out) == {"x", "x_dot", "x_ddot", "x_dddot", "x_ddddot", "yaw", "yaw_dot", "yaw_ddot"}
    assert np.allclose(out["x_ddot"], wall_plan(wall_plan.t0 + 0.3, 2))
    end = wall_plan.to_rotorpy().update(100.0)  # held at the end point
    assert np.allclose(end["x"], wall_plan(wall_plan.tf))


@pytest.mark.parametrize("bad", [math.nan, math.inf, None, [0.3], {}, 1j, "1.0", True, np.bool_(True), np.array([0.1, 0.2]),
                                 __import__("datetime").datetime(2024, 1, 1)])
def test_rotorpy_adapter_checks_its_time_as_the_trajectory_does(wall_plan: avp.Trajectory, bad) -> None:
    """``update(nan)`` was a KernelError, ``None``, a list, a dict, a complex number or a date a
    TypeError, and ``"1.0"`` and ``True`` were evaluated as times."""
    adapter = wall_plan.to_rotorpy()
    with pytest.raises(avp.ConfigError) as exc:
        adapter.update(bad)
    assert exc.value.field == "t"
    from fractions import Fraction

    for good, same in ((1, 1.0), (np.float64(0.5), 0.5), (np.array(0.5), 0.5), (Fraction(1, 2), 0.5), (-1.0, 0.0)):
        np.testing.assert_array_equal(adapter.update(good)["x"], adapter.update(same)["x"])  # held at 0 below it


def test_trajectory_rejects_nan_coefficients() -> None:
    c = np.zeros((1, 4, 3))
    c[0, 0, 1] = np.nan
    with pytest.raises(avp.ConfigError, match="NaN"):
        avp.Trajectory(c, [0.0, 1.0])


@pytest.mark.parametrize("bad", ["0.5", None, True, [0.1, "0.2"], b"1", [0.5, True], 10**400, [0.1, 10**400],
                                 [[True, 0.5]], [np.array(True), 0.5], [[0.2], [True]]])
def test_times_that_are_not_numbers_are_typed_errors(bad) -> None:
    """A string, None or a boolean is no time (``"0.5"`` was evaluated at 0.5 s, ``None`` was
    reported as NaN)."""
    traj = avp.Trajectory(np.ones((2, 4, 8)), [0.0, 1.0, 2.0])
    with pytest.raises(avp.ConfigError) as exc:
        traj(bad)
    assert exc.value.field == "t" and "expected times" in str(exc.value)
    assert traj(np.array([0, 1])).shape == (2, 3) and traj(1).shape == (3,)  # integers are times
    from decimal import Decimal
    from fractions import Fraction

    for exact in (Fraction(1, 2), Decimal("0.5"), np.array([Fraction(1, 2)], dtype=object)):  # numbers as objects
        np.testing.assert_array_equal(np.reshape(traj(exact), 3), traj(0.5))


def test_sample_grids_are_cached_read_only_and_their_copies_are_the_callers() -> None:
    """The relative sample grid is cached (the SQP's scores share one) and read-only: it cannot
    be made writable, and writing into what ``sample`` returns does not change a later call."""
    tr = avp.Trajectory(np.zeros((1, 4, 2)), [0.0, 1.0])
    for dt in (0.1, 1e-4):  # a cached grid, and one too long to cache
        grid = tr._sample_rel(dt)
        assert not grid.flags.writeable
        with pytest.raises(ValueError):
            grid.setflags(write=True)
        assert np.array_equal(grid, np.minimum(dt * np.arange(grid.size), 1.0)) and grid[-1] == 1.0
        out = tr.sample(dt)
        out[1] = 7.0
        assert tr.sample(dt)[1] == dt
    assert tr._sample_rel(0.1) is not tr._sample_rel(0.1) and np.shares_memory(tr._sample_rel(0.1), tr._sample_rel(0.1))
