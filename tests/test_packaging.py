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


def test_commands_that_track_nothing_do_not_load_the_trackers():
    """Tracker options are built only for the commands that track (they import the trackers)."""
    code = (
        "import sys; from strain2d.cli import _build_parser;"
        "_build_parser().parse_args(['study', '--out', 'x']);"
        "print('strain2d.trackers.dic' in sys.modules)"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "False"
    code = code.replace("['study', '--out', 'x']", "['track', 'v.avi', '--out', 'x']")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "True"
