import subprocess
import sys


def test_import_strain2d_stays_light():
    """Heavy dependencies load only where they are used."""
    code = (
        "import sys, strain2d, surface_strain, sample_data_synth, mpm3d, stereo;"
        "heavy = [m for m in ('cv2', 'pyvista', 'vtk', 'matplotlib', 'torch', 'skimage', 'tqdm')"
        " if m in sys.modules]; print(','.join(heavy))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == ""
