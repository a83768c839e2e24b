"""Figures rendered headless (Agg): what they show, and the core without matplotlib."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp

pytest.importorskip("matplotlib")

from avp.plotting import (
    PAD_HALF_SIZE,
    animate_run,
    euler_zxy,
    figure_plan,
    pad_corners,
    plot_plan,
    pyplot,
)


def _find(fig, gid):
    return [a for ax in fig.axes for a in ax.get_children() if a.get_gid() == gid]


@pytest.fixture(scope="module")
def wall():
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(45))
    state = avp.State.hover([0.0, 0.0, 2.5])
    return state, target, avp.plan_detailed(state, target)


def test_solved_plan_figure(wall, tmp_path: Path) -> None:
    _, target, result = wall
    cfg = avp.PlannerConfig()
    fig = figure_plan(result, target, config=cfg, ground_z=0.0, title="t")
    try:
        ax3 = fig.axes[0]
        spans = [hi - lo for lo, hi in (ax3.get_xlim(), ax3.get_ylim(), ax3.get_zlim())]
        # one scale on every axis (box sides proportional to the ranges): a 45 deg pad looks 45 deg
        aspect = np.asarray(ax3.get_box_aspect())
        assert np.allclose(aspect / aspect[0], np.asarray(spans) / spans[0])
        assert len(_find(fig, "pad")) == 1
        # the pad drawn is the real pad: side 2 * half size, in the pad plane, about its centre
        verts = pad_corners(target)
        sides = np.linalg.norm(np.diff(np.vstack([verts, verts[:1]]), axis=0), axis=1)
        assert np.allclose(sides, 2 * PAD_HALF_SIZE)
        assert np.allclose((verts - target.point) @ target.s3, 0.0, atol=1e-12)
        assert np.allclose(verts.mean(axis=0), target.point)
        assert _find(fig, "ground")
        (tmax,) = _find(fig, "thrust_max")
        assert tmax.get_ydata()[0] == pytest.approx(cfg.limits.accel_max)
        (tilt,) = _find(fig, "tilt-rate limit")
        assert tilt.get_ydata()[0] == pytest.approx(cfg.limits.tilt_rate_max)
        assert not _find(fig, "stamp")
        assert "SOLVED" in fig._suptitle.get_text()
        # knots as vertical lines on every time axis: interior knots of the plan
        time_axes = fig.axes[1:]
        assert len(time_axes) == 5
        xs = {round(float(line.get_xdata()[0]), 9) for line in time_axes[0].lines if line.get_linestyle() == ":"}
        interior = {round(float(k - result.trajectory.t0), 9) for k in result.trajectory.knots[1:-1]}
        assert xs == interior
    finally:
        pyplot().close(fig)
    out = plot_plan(result, target, tmp_path / "plan.png", config=cfg, ground_z=0.0)
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_failed_and_relaxed_plans_are_stamped(wall) -> None:
    state, target, _ = wall
    tight = dataclasses.replace(avp.PlannerConfig(), limits=avp.VehicleLimits(tilt_rate_max=0.05))
    failed = avp.plan_detailed(state, target, tight)
    assert failed.trajectory is not None and not failed.bounds.certified
    fig = figure_plan(failed, target, config=tight)
    try:
        (stamp,) = _find(fig, "stamp")
        assert stamp.get_text() == "FAILED"
        assert fig._suptitle.get_text().split("\n")[1].startswith("FAILED")
    finally:
        pyplot().close(fig)
    # a 3 m wall with a 2.5 rad/s tilt-rate limit and 1.93 s certifies only after relaxations
    relaxed_cfg = dataclasses.replace(avp.PlannerConfig(), limits=avp.VehicleLimits(tilt_rate_max=2.5),
                                      time_allocation=avp.TimeAllocation(nominal_acceleration=2.0))
    wall_target = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.pi / 2)
    relaxed = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), wall_target, relaxed_cfg)
    assert relaxed.relaxations and relaxed.trajectory is not None
    fig = figure_plan(relaxed, wall_target, config=relaxed_cfg)
    try:
        (stamp,) = _find(fig, "stamp")
        assert stamp.get_text() == "RELAXED"
        assert "relaxed: " in fig._suptitle.get_text()
    finally:
        pyplot().close(fig)


@settings(max_examples=50, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-3.1, 3.1), st.floats(-3.1, 3.1))
def test_euler_zxy_inverts_the_construction(roll: float, pitch: float, yaw: float) -> None:
    c, s = math.cos, math.sin
    Rz = np.array([[c(yaw), -s(yaw), 0], [s(yaw), c(yaw), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, c(roll), -s(roll)], [0, s(roll), c(roll)]])
    Ry = np.array([[c(pitch), 0, s(pitch)], [0, 1, 0], [-s(pitch), 0, c(pitch)]])
    got = euler_zxy(Rz @ Rx @ Ry)
    assert np.allclose(got, [roll, pitch, yaw], atol=1e-9)


def test_euler_zxy_of_a_wall_perch_is_regular(wall) -> None:
    """At a 90 deg wall the plan pitches to -90 deg; Z-X-Y angles stay continuous there."""
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    traj = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), target)
    eul = euler_zxy(traj.attitude(traj.sample(1e-3)))
    assert eul[-1, 1] == pytest.approx(-math.pi / 2, abs=1e-9)
    assert np.max(np.abs(np.diff(eul, axis=0))) < 0.05


def test_core_plans_and_cli_runs_without_matplotlib(tmp_path: Path) -> None:
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "import math, avp\n"
        "traj = avp.plan(avp.State.hover([0, 0, 1.5]), avp.PerchTarget.from_incline([3.5, 0, 1.5], math.pi / 2))\n"
        "assert 'matplotlib' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
        "from avp.cli import main\n"
        "sys.exit(main(['demo', '--output', 'x.png']))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'pip install "avp[plot]"' in proc.stderr
    assert not (tmp_path / "x.png").exists()


def test_closed_loop_run_animates(tmp_path: Path) -> None:
    from PIL import Image

    from avp.sim.run import SimScenario, simulate

    run = simulate(SimScenario(distance=1.5), "avp", seed=2)
    out = animate_run(run, tmp_path / "run.gif", fps=4)
    with Image.open(out) as im:
        duration = run.path_t[-1] - run.path_t[0]
        assert im.format == "GIF" and im.n_frames == int(duration / 0.5 * 4) + 1


def test_plot_in_view_uses_the_drag_aware_camera():
    """With VehicleLimits.rotor_drag the figure's "in view" share is the visibility of the
    drag-aware attitude (the planner's own score), not the drag-free one."""
    import re

    from avp.metrics import visibility

    cfg = avp.PlannerConfig()
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(cfg.limits, rotor_drag=0.35))
    target = avp.PerchTarget.from_incline([6.0, 0.0, 1.5], math.pi / 2)
    result = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target, cfg)

    def share(config):
        fig = figure_plan(result, target, config=config)
        text = fig._suptitle.get_text()
        pyplot().close(fig)
        return int(re.search(r"in view (\d+)% of the time", text).group(1))

    with_drag = visibility(result.trajectory, target, cfg.fov.camera, rotor_drag=0.35).time_fraction
    without = visibility(result.trajectory, target, cfg.fov.camera).time_fraction
    assert abs(with_drag - without) > 0.05  # the case tells them apart
    assert abs(share(cfg) - 100 * with_drag) <= 1.0
    assert abs(share(avp.PlannerConfig()) - 100 * without) <= 1.0


def test_plot_draws_the_drag_aware_thrust_and_attitude():
    """With VehicleLimits.rotor_drag the thrust, tilt-rate and attitude histories are those of
    ``a + g e3 + d v`` (what the certificates bound), not of the drag-free ``a + g e3``: at the
    wall's contact the drawn pitch is the pad's -90 deg."""
    d = 0.6
    cfg = avp.PlannerConfig()
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(cfg.limits, rotor_drag=d))
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    result = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target, cfg)
    traj = result.trajectory
    assert traj is not None
    fig = figure_plan(result, target, config=cfg)
    try:
        thrust_line = fig.axes[1].lines[0]
        pitch_line = fig.axes[3].lines[1]
        tt = np.asarray(thrust_line.get_xdata())
        der = traj.derivatives(traj.t0 + tt, (1, 2))
        drag_aware = np.linalg.norm(der[1, :, :3] + d * der[0, :, :3] + [0.0, 0.0, traj.g], axis=1)
        drag_free = np.linalg.norm(der[1, :, :3] + [0.0, 0.0, traj.g], axis=1)
        assert np.max(np.abs(drag_aware - drag_free)) > 0.5  # the case tells them apart
        assert np.allclose(thrust_line.get_ydata(), drag_aware, rtol=1e-9, atol=1e-9)
        assert float(np.asarray(pitch_line.get_ydata())[-1]) == pytest.approx(-90.0, abs=1e-6)
    finally:
        pyplot().close(fig)


def test_a_figure_of_another_target_model_is_a_typed_error(wall) -> None:
    _, _, result = wall
    line = avp.LineTarget.segment([2.0, -1.0, 2.0], [2.0, 1.0, 2.0])
    with pytest.raises(avp.ConfigError) as exc:
        figure_plan(result, line)
    assert exc.value.field == "target"
