"""avp.sim.limit: the ideal perch on a run's own estimates (an approximate bound for the closed loop)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from avp import PerchTarget
from avp.errors import ConfigError
from avp.sim import RigidBodyState
from avp.sim.contact import PerchPad, detect_contact
from avp.sim.evaluate import SimConfig
from avp.sim.limit import estimate_before, estimate_limit, ideal_perch
from avp.sim.run import Mode, simulate


@pytest.fixture(scope="module")
def wall_run():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(SimConfig().scenario(90, 4.5), Mode.AVP, seed=1)


def _pad(incline: float) -> PerchPad:
    normal = np.array([-math.sin(incline), 0.0, math.cos(incline)])
    t = PerchTarget.from_normal([4.0, 0.0, 2.0], normal)
    return PerchPad(t.point, t.R_WS)


@settings(max_examples=60, deadline=None)
@given(incline=st.floats(0.3, math.pi / 2), depth=st.floats(-0.05, 0.05), v_n=st.floats(0.1, 2.0),
       v_s1=st.floats(-3.0, 3.0))
def test_the_ideal_perch_is_judged_where_the_simulator_detects_the_crossing(incline, depth, v_n, v_s1):
    """An estimate ``depth`` behind the true plane is hit early: the simulator's own crossing
    detector, run on the straight path between two states, finds the same point and time."""
    pad = _pad(incline)
    est = PerchTarget(point=pad.p_W - depth * pad.R_WS[:, 2], R_WS=pad.R_WS)
    v_S = np.array([v_s1, 0.0, -v_n])
    t_f = 3.0
    out = ideal_perch(est, pad, v_S, t_f)
    v_W = pad.R_WS @ v_S
    if depth <= 0.0:  # in front of the plane (or on it): judged at t_f, short of the plane
        assert out.t == t_f
        np.testing.assert_allclose(out.error_S, [0.0, 0.0, -depth], atol=1e-12)
        return
    # straight path from 1 s before to 1 s after t_f; detect_contact interpolates the crossing
    prev = RigidBodyState(est.point - v_W, v_W, pad.R_WS)
    new = RigidBodyState(est.point + v_W, v_W, pad.R_WS)
    hit = detect_contact(prev, new, pad, t_f - 1.0, t_f + 1.0)
    assert hit is not None
    assert out.t == pytest.approx(hit.t, abs=1e-12)
    np.testing.assert_allclose(out.error_S[:2], hit.p_S[:2], atol=1e-12)
    assert abs(out.error_S[2]) < 1e-12
    # the slide turns the depth into an in-plane error, |v_s1| / v_n of it along s1
    assert out.error_S[0] == pytest.approx(-depth * v_s1 / v_n, rel=1e-9, abs=1e-12)


def test_the_ideal_vehicle_carries_the_odometry_drift_it_shares_with_the_detections():
    """Detections composed with a drifted pose put the pad ``drift`` off; the vehicle flying
    the same drifted pose lands on the true pad."""
    pad = _pad(1.0)
    drift = np.array([0.004, -0.007, 0.011])
    est = PerchTarget(point=pad.p_W + drift, R_WS=pad.R_WS)
    v_S = np.array([-1.0, 0.0, -0.3])
    exact = ideal_perch(est, pad, v_S, 2.0, drift=drift)
    np.testing.assert_allclose(exact.error_S, 0.0, atol=1e-12)
    assert exact.success and exact.t == 2.0
    off = ideal_perch(est, pad, v_S, 2.0)
    np.testing.assert_allclose(pad.R_WS @ off.error_S, drift, atol=1e-12)


def test_an_ideal_perch_that_never_reaches_the_plane_is_judged_at_the_contact_time():
    """Past the plane but not approaching it (a badly tilted estimate): no crossing, judged at
    ``t_f`` like a run without contact; a non-finite velocity is a typed error."""
    pad = _pad(math.pi / 2)
    est = PerchTarget(point=pad.p_W - 0.02 * pad.R_WS[:, 2], R_WS=pad.R_WS)
    out = ideal_perch(est, pad, np.array([-2.0, 0.0, 0.0]), 1.0)
    assert out.t == 1.0 and "plane" not in out.failures and out.error_S[2] == pytest.approx(-0.02)
    with pytest.raises(ConfigError, match="v_S"):
        ideal_perch(est, pad, np.array([np.nan, 0.0, -0.3]), 1.0)


def test_refusing_all_detections_reproduces_the_runs_own_filter(wall_run):
    """Re-fused from every detection, the estimate is the one the run's filter ended with (its
    error is recorded independently, after each detection, in ``result.detections``)."""
    r = wall_run
    tau = r.final_plan.tf - r.measurements[-1].t_delivered
    est = estimate_before(r, tau)
    truth = r.scenario.target()
    assert float(np.linalg.norm(est.point - truth.point)) == pytest.approx(r.detections[-1, 3], rel=1e-9)


def test_known_scale_removes_an_exact_scale_error(wall_run):
    """With noise-free detections that carry only the scale error, the known-scale estimate
    is the pad itself, and the filter's is not."""
    r = wall_run
    b = 0.03
    truth = r.scenario.target()
    exact = tuple(dataclasses.replace(m, p_W=m.p_cam_W + (1.0 + b) * (truth.point - m.p_cam_W), R_WS=truth.R_WS,
                                      sigma_pos=1e-4) for m in r.measurements)
    fake = dataclasses.replace(r, measurements=exact, detector_scale=b)
    known = estimate_before(fake, 0.0, known_scale=True)
    np.testing.assert_allclose(known.point, truth.point, atol=1e-9)
    # the run's own filter fits the scale from the approach: close, but not exact (its prior)
    assert 1e-9 < np.linalg.norm(estimate_before(fake, 0.0).point - truth.point) < 0.01
    plain = dataclasses.replace(fake, scenario=dataclasses.replace(r.scenario, filter_estimate_scale=False))
    assert np.linalg.norm(estimate_before(plain, 0.0).point - truth.point) > 0.01


def test_the_recorded_drift_is_what_the_detections_carry():
    """With an exact detector and odometry that only drifts, a detection's error is the drift of
    the believed pose it was composed with (odometry.py: believed = true + drift), as
    ``path_drift`` records it at the capture time."""
    cfg = SimConfig(camera_noise_scale=0.0, camera_scale_bias=0.0, camera_normal_tilt_deg=0.0, camera_latency=0.0,
                    odometry_sigma_p=0.0, odometry_sigma_v=0.0, odometry_sigma_att_deg=0.0, odometry_drift=0.02,
                    filter_scale_error=0.0, filter_estimate_scale=False, aim_normal=0.0, aim_slope=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(cfg.scenario(90, 4.5), Mode.AVP, seed=2)
    truth = r.scenario.target().point
    checked = 0
    for m in r.measurements:
        i = int(np.searchsorted(r.path_t, m.t))
        if i < r.path_t.size and abs(r.path_t[i] - m.t) < 1e-9:
            np.testing.assert_allclose(m.p_W - truth, r.path_drift[i], atol=1e-9)
            checked += 1
    assert checked >= 5
    assert np.max(np.abs(r.path_drift)) > 1e-3  # the drift did move


def test_aiming_at_the_true_plane_leaves_no_plane_or_early_contact_failure(wall_run):
    """The offset is along the *estimated* normal: shifting by minus the estimate's error along
    the true normal lands on the plane up to the tilt between the two normals."""
    lims = estimate_limit(wall_run, (0.45,))
    assert len(lims) == 1
    lim = lims[0]
    s3 = wall_run.scenario.target().s3
    for which, est in enumerate((lim.filter, lim.known_scale)):
        v_n = abs(float((est.R_WS @ lim.v_S) @ s3))  # the approach speed along the true normal
        n = lim.normal_error[which]
        out = lim.judge(-n)[which]
        assert out is not None
        residual = abs(n) * (1.0 - float(est.s3 @ s3)) + 1e-12
        assert abs(out.error_S[2]) <= residual
        assert "plane" not in out.failures
        assert lim.t_f - residual / v_n - 1e-12 <= out.t <= lim.t_f


def test_the_estimate_limit_refuses_a_moving_pad():
    from avp.sim.run import PlatformMotion

    sc = dataclasses.replace(SimConfig(aim_normal=0.0, aim_slope=0.0).scenario(30, 4.5),
                             platform=PlatformMotion(speed=1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(sc, Mode.ONE_SHOT, seed=0, max_time=0.2)
    with pytest.raises(ConfigError, match="static pad"):
        estimate_before(r, 0.3)


def test_aiming_down_the_slope_moves_the_ideal_contact_down_by_the_offset(wall_run):
    """``judge(0, d)`` aims ``d`` along the estimate's ``s1``: a contact judged at ``t_f`` moves
    by ``d`` along the true ``s1`` (to the tilt between the frames)."""
    lim = estimate_limit(wall_run, (0.25,))[0]
    n = lim.normal_error[0]
    base = lim.judge(-n + 0.01)[0]  # 1 cm in front of the plane: judged at t_f, no crossing
    down = lim.judge(-n + 0.01, -0.05)[0]
    assert base.t == down.t == pytest.approx(lim.t_f)
    assert down.error_S[0] - base.error_S[0] == pytest.approx(-0.05, abs=2e-3)
