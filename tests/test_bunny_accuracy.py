"""Issue 3, point 6: PRT against the brute-force ground truth on the Stanford bunny scaled to
10 cm, marble, skin1 and ketchup at 32 coefficients: < 1 % area-weighted relative RMS.
(The full figure, 300 receivers, is printed by blender_scripts/accuracy_prt.py.)"""

import sys

import pytest

from blender_scripts.lib import accuracy, models
from conftest import REPO

pytestmark = pytest.mark.slow


@pytest.mark.skipif(not (models.MODELS / "stanford-bunny.obj").exists(), reason="../shared/models is not beside the repo")
def test_prt_within_one_percent_of_ground_truth_on_the_bunny():
    rows = accuracy.evaluate("stanford-bunny.obj", receivers=60, coefficients=32, rel_tol=1e-3)
    for r in rows:
        assert max(r["rms"]) < 0.01, r
        # The ground truth states its own uncertainty (difference of its last two levels;
        # the node cap stops the bunny at level 2, measured 0.3-0.6 %): it must lie below the
        # bound it judges, or the comparison says nothing.
        assert r["reference_error"] < 1e-2, r


def test_demo_main_job_runs_end_to_end(tmp_path):
    import subprocess

    out = subprocess.run(
        [sys.executable, str(REPO / "blender_scripts" / "demo.py"), "--out", str(tmp_path),
         "--presets", "marble", "--receivers", "20", "--cycles-samples", "4"],
        capture_output=True, text=True, timeout=600,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "error against ground truth" in out.stdout
    assert (tmp_path / "marble.png").stat().st_size > 1000
    assert (tmp_path / "marble_vs_cycles.png").stat().st_size > 1000
