import subprocess
import sys

import pytest


def test_import_strain2d_stays_light():
    """Heavy dependencies load only where they are used."""
    code = (
        "import sys, strain2d, surface_strain, sample_data_synth, mpm3d;"
        "heavy = [m for m in ('cv2', 'pyvista', 'vtk', 'matplotlib', 'torch', 'skimage', 'tqdm')"
        " if m in sys.modules]; print(','.join(heavy))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == ""


@pytest.mark.parametrize("package", ["stereo"])
def test_placeholders_say_they_are_not_implemented(package):
    res = subprocess.run([sys.executable, "-m", package, "analyze"], capture_output=True, text=True)
    assert res.returncode == 2
    assert "not implemented" in res.stderr and len(res.stderr.strip().splitlines()) == 1
