"""The main job: ``avp demo`` prints a summary and writes a plot."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from avp.cli import main


def test_demo_prints_summary_and_writes_png(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo.png"
    assert main(["demo", "--output", str(out)]) == 0
    text = capsys.readouterr().out
    for key in ("duration", "contact position", "attitude error", "contact velocity", "peak thrust", "solve time"):
        assert key in text
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"\x89PNG"


def test_demo_flags_and_module_entry_point(tmp_path: Path) -> None:
    out = tmp_path / "floor.png"
    proc = subprocess.run(
        [sys.executable, "-m", "avp", "demo", "--incline-deg", "30", "--distance", "1.5",
         "--lateral", "0.3", "--solver", "proxqp", "--output", str(out)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,  # not the checkout: its avp/ has no .so
    )
    assert proc.returncode == 0, proc.stderr
    assert "30 deg pad" in proc.stdout and out.exists()


def test_demo_bad_solver_is_a_clean_error(capsys) -> None:
    assert main(["demo", "--solver", "nope", "--no-plot"]) == 2
    assert "not installed" in capsys.readouterr().err


def test_import_and_module_entry_from_the_clone_root() -> None:
    """After the README's editable install, the checkout's ``avp/`` is the installed package (it
    holds the compiled module), so running from the clone root works."""
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run([sys.executable, "-c", "import avp, avp._avp_rust; print(avp.__file__)"],
                          capture_output=True, text=True, timeout=60, cwd=root)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip()).resolve().parent == root / "avp"
