"""Visibility metric (Tables I, III) on trajectories with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from avp import Camera, Trajectory, Visibility, visibility
from avp.errors import ConfigError
from avp.types import PerchTarget

TARGET_HEIGHT = 1.0
EDGE = 2.0 - TARGET_HEIGHT / math.tan(math.radians(35.0))  # x where the target leaves the cone


def _hover_then_cruise() -> Trajectory:
    """Hover at the origin for 1 s (yaw 0), then fly along +x at 1 m/s for 4 s (zero acceleration:
    level attitude, camera along +x)."""
    c = np.zeros((2, 4, 2))
    c[1, 0] = [0.0, 1.0]  # x = t - 1 on the second segment
    return Trajectory(c, [0.0, 1.0, 5.0])


def _target(point) -> PerchTarget:
    return PerchTarget.from_incline(point, math.radians(90.0))


def test_known_fractions() -> None:
    """Target 2 m ahead and 1 m up: visible while 1/(2 - x) <= tan 35 deg, i.e. x <= EDGE."""
    vis = visibility(_hover_then_cruise(), _target([2.0, 0.0, TARGET_HEIGHT]), dt=1e-3)
    assert isinstance(vis, Visibility)
    assert vis.time_fraction == pytest.approx((1.0 + EDGE) / 5.0, abs=2e-3)
    assert vis.path_fraction == pytest.approx(EDGE / 4.0, abs=2e-3)
    assert vis.first_loss == pytest.approx(1.0 + EDGE, abs=2e-3)


def test_target_behind_is_never_visible() -> None:
    """The one-sided cone: a target straight behind the camera does not count."""
    vis = visibility(_hover_then_cruise(), _target([-3.0, 0.0, 0.0]))
    assert vis.time_fraction == 0.0 and vis.path_fraction == 0.0


def test_range_and_rectangular_fov() -> None:
    target = _target([2.0, 0.0, TARGET_HEIGHT])
    assert visibility(_hover_then_cruise(), target, Camera(range=1.0)).time_fraction == 0.0
    # A 40 deg vertical image (20 deg half) loses the target (26.6 deg up at the start) at once.
    narrow = visibility(_hover_then_cruise(), target, Camera(vertical_fov=math.radians(40.0)))
    assert narrow.time_fraction == 0.0
    wide = visibility(_hover_then_cruise(), target, Camera(vertical_fov=math.radians(100.0)))
    assert wide.time_fraction == pytest.approx((1.0 + EDGE) / 5.0, abs=2e-3)


def test_finer_grid_converges() -> None:
    target = _target([2.0, 0.0, TARGET_HEIGHT])
    coarse = visibility(_hover_then_cruise(), target, dt=1e-2)
    fine = visibility(_hover_then_cruise(), target, dt=1e-4)
    assert abs(coarse.time_fraction - fine.time_fraction) < 5e-3


def test_bad_dt() -> None:
    with pytest.raises(ConfigError, match="dt"):
        visibility(_hover_then_cruise(), _target([2.0, 0.0, 1.0]), dt=0.0)


def test_visibility_many_equals_one_at_a_time() -> None:
    """One vectorised pass over several plans gives exactly the per-plan answers (same knots in
    one kernel call; different knots fall back to one call each)."""
    from avp.metrics import visibility_many

    rng = np.random.default_rng(5)
    knots = [0.0, 0.7, 1.6, 2.4]
    trajs = []
    for _ in range(3):
        c = rng.normal(0.0, 0.4, (3, 4, 8))
        c[:, 0, 0] += -2.0
        trajs.append(Trajectory(c, knots))
    other = Trajectory(rng.normal(0.0, 0.4, (2, 4, 8)), [0.0, 1.0, 2.2])
    target = _target([2.0, 0.0, TARGET_HEIGHT])
    cam = Camera(half_fov=math.radians(50.0))
    for dt in (1e-2, 2.4 / 200):
        many = visibility_many(trajs + [other], target, cam, dt)
        one = [visibility(t, target, cam, dt) for t in trajs + [other]]
        assert many == one
        assert visibility_many(trajs, target, cam, dt) == one[:3]
    assert any(v.time_fraction not in (0.0, 1.0) for v in one)  # the case is not trivial
    assert visibility_many([], target) == []


def test_bad_inputs_are_config_errors_naming_the_argument() -> None:
    """A lone plan, a non-iterable, a string, an iterator's wrong element, a line or a camera
    class: a ConfigError naming the argument (an iterator of plans is taken), the single-plan
    function naming its own argument ``trajectory``."""
    from avp.metrics import visibility_many

    tr, target = _hover_then_cruise(), _target([2.0, 0.0, TARGET_HEIGHT])
    assert visibility_many(iter([tr]), target) == [visibility(tr, target)]
    for bad in (tr, 5, None, "ab", {"a": tr}, np.array(5.0)):
        with pytest.raises(ConfigError, match=r"^trajectories: must be a sequence of avp.Trajectory"):
            visibility_many(bad, target)
    with pytest.raises(ConfigError, match=r"^trajectories\[1\]: expected avp.Trajectory, got int"):
        visibility_many([tr, 3], target)
    with pytest.raises(ConfigError, match=r"^trajectory: expected avp.Trajectory, got tuple"):
        visibility((tr,), target)
    for call in (visibility, lambda t, *a: visibility_many((t,), *a)):
        with pytest.raises(ConfigError, match=r"^target: expected avp.PerchTarget"):
            call(tr, target.point)
        with pytest.raises(ConfigError, match=r"^camera: expected avp.Camera or None, got type"):
            call(tr, target, Camera)
        for dt in ("0.1", None, [1e-3], math.nan):
            with pytest.raises(ConfigError, match=r"^dt: "):
                call(tr, target, None, dt)


@pytest.mark.parametrize("incline", [0, 45, 90, 120])
def test_cone_only_fast_path_equals_the_camera_test(incline) -> None:
    """A cone-only camera is scored by the Rust FoV kernel, a camera with a range by
    Camera.sees on the attitude (11), (13): with a range no sample reaches, both agree. The
    kernel sums the trapezoid weights one sample after the other, NumPy by BLAS dot products,
    so the fractions agree to rounding (1e-12); one sample seen differently would move them by
    about dt / T = 1e-3, and the first loss, a sample time, must be the same."""
    import avp

    target = PerchTarget.from_incline([0.0, 0.0, 1.5], math.radians(incline))
    state = avp.State.hover([-3.0, 0.5, 1.5 + (1.0 if incline < 45 else 0.0)])
    traj = avp.plan(state, target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)), allow_relaxed=True)
    for half in (math.radians(20), math.radians(35), math.radians(60)):
        cone = visibility(traj, target, Camera(half_fov=half), dt=2e-3)
        generic = visibility(traj, target, Camera(half_fov=half, range=1e6), dt=2e-3)
        assert cone.first_loss == generic.first_loss
        assert cone.time_fraction == pytest.approx(generic.time_fraction, rel=1e-12, abs=1e-12)
        assert cone.path_fraction == pytest.approx(generic.path_fraction, rel=1e-12, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 3), drag=st.sampled_from([0.0, 0.3, 0.8]),
       half=st.floats(15.0, 70.0), steps=st.integers(2, 400))
def test_the_cone_kernel_counts_what_camera_sees_counts(seed: int, k: int, drag: float, half: float,
                                                          steps: int) -> None:
    """The cone-only score (one kernel call that evaluates the plans and tests the cone) against
    the general NumPy path (``Camera.sees`` on the flatness attitude), taken with a range no
    sample reaches: the same fractions and first loss, for one to three plans on the same knots,
    with and without rotor drag, on dense and coarse grids."""
    from avp.metrics import visibility_many

    rng = np.random.default_rng(seed)
    knots = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 1.5, int(rng.integers(1, 4))))])
    trajs = []
    for _ in range(k):
        c = rng.normal(0.0, 0.5, (knots.size - 1, 4, 8))
        c[:, 0, 0] -= 2.0
        trajs.append(Trajectory(c, knots))
    target = _target(rng.normal(0.0, 1.0, 3) + np.array([2.0, 0.0, 0.0]))
    cone = Camera(half_fov=math.radians(half))
    far = Camera(half_fov=math.radians(half), range=1e9)
    dt = float(knots[-1]) / steps
    fast = visibility_many(trajs, target, cone, dt, rotor_drag=drag)
    slow = visibility_many(trajs, target, far, dt, rotor_drag=drag)
    for a, b in zip(fast, slow, strict=True):
        assert a.time_fraction == pytest.approx(b.time_fraction, abs=1e-12)
        assert a.path_fraction == pytest.approx(b.path_fraction, abs=1e-12)
        assert (a.first_loss is None) == (b.first_loss is None)
        if a.first_loss is not None:
            assert a.first_loss == b.first_loss
