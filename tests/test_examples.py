"""The examples run as a user would run them (outside the checkout: its avp/ may lack the .so)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_replan_loop_example(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(EXAMPLES / "replan_loop.py")], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "INITIAL_PLAN" in out and "REPLANNED" in out and "FROZEN_NEAR_CONTACT" in out
    last = out.strip().splitlines()[-1]
    assert last.startswith("contact at t=")
    assert float(last.split(",")[1].split("cm")[0]) < 1.0  # converged on the true pad


def test_plan_once_example(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(EXAMPLES / "plan_once.py")], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("status: solved")
    assert "bounds certified" in proc.stdout and "rotorpy flat output" in proc.stdout


def test_visibility_sweep_example_writes_table_and_heatmap(tmp_path: Path) -> None:
    out = tmp_path / "sweep.png"
    proc = subprocess.run([sys.executable, str(EXAMPLES / "visibility_sweep.py"), "--out", str(out)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    rows = [line for line in proc.stdout.splitlines() if "|" in line and "%" in line]
    assert len(rows) == 6  # free, -3, -2, -1, 0, +1 slide rows
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_moving_perch_example(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(EXAMPLES / "moving_perch.py")], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("status: SOLVED")
    assert "bounds certified: True" in proc.stdout and "clearance: certified" in proc.stdout


def test_background_loop_example(tmp_path: Path) -> None:
    """The loop of a replanner in a worker process perches on the true pad, adopting the worker's
    steps (whether in time depends on this machine's load: not asserted)."""
    proc = subprocess.run([sys.executable, str(EXAMPLES / "background_loop.py")], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "adopted the step of t=0.000 s: INITIAL_PLAN" in out and ": REPLANNED" in out
    last = out.strip().splitlines()[-1]
    assert last.startswith("contact at t=")
    assert float(last.split(",")[1].split("cm")[0]) < 1.0  # converged on the true pad
