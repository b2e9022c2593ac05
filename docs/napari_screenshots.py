"""Take the napari guide's pictures headless: each widget after a run on synthetic data.

    QT_QPA_PLATFORM=xcb xvfb-run -a -s '-screen 0 1600x1000x24' python docs/napari_screenshots.py

Renders a speckle video under a Gaussian local contraction and a folded z-stack
(``sample_data_synth``), opens them in napari with the plugin's readers, runs each
widget as a user would (a rectangle
drawn on the video, a 7 x 7 grid, the default tracker; the stack's folds), waits for the
runs and saves the whole window.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
IMAGES = ROOT / "docs" / "images"


def _wait(widget, app, limit: float = 600.0) -> None:
    start = time.monotonic()
    while widget.last_status == "running" and time.monotonic() - start < limit:
        app.processEvents()
        time.sleep(0.05)
    if widget.last_status != "done":
        raise SystemExit(f"the run ended {widget.last_status}: {widget.status.text()}")


def main() -> int:
    import napari
    from qtpy.QtWidgets import QApplication

    from sample_data_synth import make_case, make_stack_case, write_stack, write_video
    from tissue_napari.readers import read_path
    from tissue_napari.widgets import MpmWidget, RunNumbersWidget, StrainWidget, add_layers

    tmp = Path(tempfile.mkdtemp(prefix="napari_shots_"))
    video = tmp / "gaussian.avi"
    case = make_case("gaussian", size=400, n_frames=16, rng=0)
    write_video(case.frames, video)
    x0, y0, x1, y1 = case.truth.roi

    viewer = napari.Viewer(title="tissue-strain", show=True)
    viewer.window.resize(1400, 900)
    app = QApplication.instance()
    add_layers(viewer, read_path(str(video)))
    corners = np.array([[0, y0, x0], [0, y0, x1], [0, y1, x1], [0, y1, x0]])
    viewer.add_shapes([corners], shape_type="rectangle", name="region", edge_color="yellow",
                      face_color="transparent", edge_width=2)  # fmt: skip
    strain = StrainWidget(viewer)
    viewer.window.add_dock_widget(strain, name="Strain from video", area="right")
    strain.region.setCurrentText("region")
    strain.out.setText(str(tmp / "run"))
    strain.preview()
    strain.run()
    _wait(strain, app)
    viewer.layers["grid preview"].visible = False
    viewer.layers["region"].visible = False
    viewer.dims.set_current_step(0, 15)
    app.processEvents()
    viewer.screenshot(str(IMAGES / "napari_strain.png"), canvas_only=False)

    numbers = RunNumbersWidget(viewer)
    viewer.window.remove_dock_widget(strain)
    viewer.window.add_dock_widget(numbers, name="Run numbers", area="right")
    viewer.layers.selection.active = viewer.layers["run nodes (Exx)"]
    app.processEvents()
    viewer.screenshot(str(IMAGES / "napari_run_numbers.png"), canvas_only=False)
    viewer.window.remove_dock_widget(numbers)

    for layer in list(viewer.layers):
        viewer.layers.remove(layer)
    stack = make_stack_case("after", size=160, spacing=(4.0, 5.0, 5.0), rng=1)
    write_stack(tmp / "after.tif", stack)
    mpm = MpmWidget(viewer)
    viewer.window.add_dock_widget(mpm, name="MPM folds", area="right")
    mpm.stack.setText(str(tmp / "after.tif"))
    mpm.out.setText(str(tmp / "mpm"))
    mpm.run()
    _wait(mpm, app)
    viewer.layers["mpm surface"].visible = False
    app.processEvents()
    viewer.screenshot(str(IMAGES / "napari_mpm.png"), canvas_only=False)
    viewer.close()
    print(f"wrote {IMAGES}/napari_strain.png, napari_run_numbers.png and napari_mpm.png")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("NAPARI_ASYNC", "0")
    sys.exit(main())
