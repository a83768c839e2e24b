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
