"""The napari widgets: strain from a video, and the folds of a multiphoton stack.

Each widget builds the command a user would type, shows it, and runs it in a child
process (:class:`CommandRunner`, Qt's ``QProcess``): the viewer stays responsive, the
progress bar follows the command's own progress lines, Cancel interrupts the child as
Ctrl-C would (the toolkit then removes what it had started to write), and the run
folder is the command line's.  When the run ends its folder is read back as layers
(:mod:`tissue_napari.readers`).
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import sys
from pathlib import Path

import numpy as np
from qtpy.QtCore import QObject, QProcess, QProcessEnvironment, Signal
from qtpy.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from tissue_core.errors import InputError

__all__ = [
    "CommandRunner",
    "MpmWidget",
    "RunNumbersWidget",
    "StrainWidget",
    "add_layers",
    "run_numbers",
]

#: a counter's line of :mod:`tissue_core.progress`: ``[  1.2 s] tracking (gdic): 10/31 frames``
_COUNTER = re.compile(r"^\[\s*[\d.]+ s\] (?P<what>.+?): (?P<done>\d+)(?:/(?P<total>\d+))? \w+$")
#: a step's line: ``[  0.3 s] writing results``
_STEP = re.compile(r"^\[\s*[\d.]+ s\] (?P<what>.+)$")
#: an error line of a command: ``strain2d analyze: error: ...`` (or the program's own)
_ERROR = re.compile(r"^\S+(?: \S+)?: error: (?P<why>.+)$")


def add_layers(viewer, layers) -> list:
    """Add reader layer tuples ``(data, kwargs, layer_type)`` to ``viewer``."""
    return [getattr(viewer, f"add_{kind}")(data, **kwargs) for data, kwargs, kind in layers]


class CommandRunner(QObject):
    """A toolkit command (``[package, command, args...]``) run as ``python -m`` in a child
    process, its progress lines turned into signals.

    Signals
    -------
    progress(done, total, what)
        A counter's line (``total`` 0 when unknown).
    step(text)
        Any other progress line.
    finished(status, message)
        ``"done"``, ``"cancelled"`` or ``"failed"``, with the command's error line.
    """

    progress = Signal(int, int, str)
    step = Signal(str)
    finished = Signal(str, str)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.process: QProcess | None = None
        self._cancelled = False
        self._error = ""
        self._buffer = ""

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.state() != QProcess.NotRunning

    def start(self, argv: list[str]) -> None:
        if self.running:
            raise InputError("a run is going on: cancel it or wait for it")
        self._cancelled, self._error, self._buffer = False, "", ""
        process = QProcess(self)
        env = QProcessEnvironment.systemEnvironment()
        env.insert("TISSUE_STRAIN_PROGRESS_INTERVAL", "0.25")  # lines often enough for a bar
        env.insert("PYTHONUNBUFFERED", "1")
        process.setProcessEnvironment(env)
        process.readyReadStandardError.connect(self._read)
        process.finished.connect(self._done)
        self.process = process
        process.start(sys.executable, ["-m", *argv])

    def cancel(self) -> None:
        """Interrupt the run as Ctrl-C would: the command removes its partial output."""
        if self.running:
            self._cancelled = True
            os.kill(int(self.process.processId()), signal.SIGINT)

    def wait(self, msecs: int = 60_000) -> bool:
        return self.process is None or self.process.waitForFinished(msecs)

    def _read(self) -> None:
        data = bytes(self.process.readAllStandardError()).decode("utf-8", "replace")
        self._buffer += data
        *lines, self._buffer = self._buffer.split("\n")
        for line in lines:
            self._line(line.rstrip("\r"))

    def _line(self, line: str) -> None:
        if m := _ERROR.match(line):
            self._error = m["why"]
        elif m := _COUNTER.match(line):
            self.progress.emit(int(m["done"]), int(m["total"] or 0), m["what"])
        elif m := _STEP.match(line):
            self.step.emit(m["what"])

    def _done(self, code: int, _status) -> None:
        self._read()
        if self._buffer:
            self._line(self._buffer)
            self._buffer = ""
        if self._cancelled:
            self.finished.emit("cancelled", "cancelled: nothing was written")
        elif code == 0:
            self.finished.emit("done", "")
        else:
            self.finished.emit("failed", self._error or f"the command ended with status {code}")


def _path_row(line: QLineEdit, *, folder: bool, save: bool = False) -> QWidget:
    """A path field with a button that opens a file dialog."""
    row = QWidget()
    lay = QHBoxLayout(row)
    lay.setContentsMargins(0, 0, 0, 0)
    lay.addWidget(line)
    button = QPushButton("…")
    button.setMaximumWidth(30)

    def browse() -> None:
        if folder and save:
            path, _ = QFileDialog.getSaveFileName(row, "Output folder")
        elif folder:
            path = QFileDialog.getExistingDirectory(row, "Folder")
        else:
            path, _ = QFileDialog.getOpenFileName(row, "File")
        if path:
            line.setText(path)

    button.clicked.connect(browse)
    lay.addWidget(button)
    return row


class _RunWidget(QWidget):
    """What both widgets share: the output, Run and Cancel, progress, the command."""

    def __init__(self, napari_viewer) -> None:
        super().__init__()
        self.viewer = napari_viewer
        self.runner = CommandRunner(self)
        self.runner.progress.connect(self._progress)
        self.runner.step.connect(self._step)
        self.runner.finished.connect(self._finished)
        self.form = QFormLayout()
        self.out = QLineEdit()
        self.out.setPlaceholderText("a new folder for the results")
        self.overwrite = QCheckBox("replace an earlier result there")
        self.run_button = QPushButton("Run")
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1)
        self.bar.setValue(0)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.command_line = QLineEdit()
        self.command_line.setReadOnly(True)
        self.command_line.setToolTip("the same run from a terminal")
        self.run_button.clicked.connect(self.run)
        self.cancel_button.clicked.connect(self.runner.cancel)
        self.last_status = ""
        self.last_layers: list = []
        # (path, write) of files the command reads, written once the inputs are good
        self._pending: list = []
        self._written: list[Path] = []  # those of the run going on
        self._run_out: Path | None = None

    def _finish_layout(self, extra: list[QWidget] = (), below: list[QWidget] = ()) -> None:
        self.form.addRow("output folder", _path_row(self.out, folder=True, save=True))
        self.form.addRow("", self.overwrite)
        buttons = QWidget()
        row = QHBoxLayout(buttons)
        row.setContentsMargins(0, 0, 0, 0)
        for widget in extra:
            row.addWidget(widget)
        row.addWidget(self.run_button)
        row.addWidget(self.cancel_button)
        outer = QVBoxLayout(self)
        outer.addLayout(self.form)
        outer.addWidget(buttons)
        outer.addWidget(self.bar)
        outer.addWidget(self.status)
        outer.addWidget(QLabel("command line:"))
        outer.addWidget(self.command_line)
        for widget in below:
            outer.addWidget(widget)
        outer.addStretch(1)

    # -- to fill in
    def command(self) -> list[str]:  # pragma: no cover - each widget's own
        raise NotImplementedError

    def load(self, folder: Path) -> list:  # pragma: no cover - each widget's own
        raise NotImplementedError

    # -- running
    def say(self, text: str, *, error: bool = False) -> None:
        self.status.setText(text)
        self.status.setStyleSheet("color: #d33;" if error else "")

    def output(self) -> Path:
        text = self.out.text().strip()
        if not text:
            raise InputError("choose an output folder")
        return Path(text).expanduser()

    def run(self) -> bool:
        """Check the inputs and start the command; False (and a message) if they are bad."""
        self._pending = []
        try:
            argv = self.command()
            for arg in argv:  # QProcess passes text: a name that is not UTF-8 would change
                try:
                    arg.encode("utf-8")
                except UnicodeEncodeError:
                    raise InputError(
                        f"{arg.encode('utf-8', 'surrogateescape')!r} is not a UTF-8 name: "
                        "rename it, or run the command in a terminal"
                    ) from None
            self._written = []
            for path, write in self._pending:  # once every check passed
                new = not path.exists()  # one there before (an earlier run's) stays
                write()
                if new:
                    self._written.append(path)
            self._run_out = self.output()
        except (InputError, OSError, ValueError) as exc:
            self.say(str(exc), error=True)
            self.last_status = "refused"
            return False
        self.command_line.setText(shlex.join(["python", "-m", *argv]))
        self.bar.setRange(0, 0)  # busy until the first counter
        self.say("starting")
        self.run_button.setEnabled(False)
        self.cancel_button.setEnabled(True)
        self.last_status = "running"
        self.runner.start(argv)
        return True

    def _progress(self, done: int, total: int, what: str) -> None:
        if total:
            self.bar.setRange(0, total)
            self.bar.setValue(done)
        self.say(f"{what}: {done}/{total}" if total else f"{what}: {done}")

    def _step(self, text: str) -> None:
        self.say(text)

    def _finished(self, status: str, message: str) -> None:
        self.run_button.setEnabled(True)
        self.cancel_button.setEnabled(False)
        self.bar.setRange(0, 1)
        self.bar.setValue(1 if status == "done" else 0)
        self.last_status = status
        if status != "done":  # nothing of a refused, failed or cancelled run is left
            for path in self._written:
                path.unlink(missing_ok=True)
        self._written = []
        if status == "done":
            out = self._run_out
            try:
                self.last_layers = self.load(out)
            except Exception as exc:  # the run is written; only showing it failed
                self.say(f"results in {out}; they could not be shown: {exc}", error=True)
                return
            self.say(f"results in {out}")
        else:
            self.say(message, error=status == "failed")


class StrainWidget(_RunWidget):
    """Strain from a video: the region drawn as a shapes layer (a rectangle, or any
    polygon) or a labels layer (the tissue mask), a grid preview, the tracker and its
    options from the tracker registry, ``strain2d analyze`` in the background, and the
    tracks, nodes and mesh coloured by strain as layers."""

    def __init__(self, napari_viewer) -> None:
        super().__init__(napari_viewer)
        from strain2d import available_trackers

        self.video = QComboBox()
        self.video_path = QLineEdit()
        self.video_path.setPlaceholderText("or a video file or image folder")
        self.region = QComboBox()
        self.grid = QLineEdit("7x7")
        self.tracker = QComboBox()
        self.trackers = {n: s for n, s in available_trackers().items() if s.needs_frames}
        self.tracker.addItems(list(self.trackers))
        self.tracker.setCurrentText("gdic")
        self.options_box = QWidget()
        self.options_form = QFormLayout(self.options_box)
        self.options_form.setContentsMargins(0, 0, 0, 0)
        self.option_fields: dict[str, QWidget] = {}
        self.scale = QLineEdit()
        self.scale.setPlaceholderText("e.g. 0.012mm/px (optional)")
        self.fps = QLineEdit()
        self.fps.setPlaceholderText("frames per second (optional)")
        self.component = QComboBox()
        self.component.addItems(["Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J"])
        self.preview_button = QPushButton("Preview grid")
        self.preview_button.clicked.connect(self.preview)
        self.form.addRow("video", self.video)
        self.form.addRow("", _path_row(self.video_path, folder=False))
        self.form.addRow("region", self.region)
        self.form.addRow("grid (columns x rows)", self.grid)
        self.form.addRow("tracker", self.tracker)
        self.form.addRow(self.options_box)
        self.form.addRow("pixel size", self.scale)
        self.form.addRow("frame rate", self.fps)
        self.form.addRow("colour by", self.component)
        self._finish_layout([self.preview_button])
        self.tracker.currentTextChanged.connect(self._tracker_options)
        self._tracker_options(self.tracker.currentText())
        self._watched: set[int] = set()
        self._chosen: dict = {}
        self._listing = False
        self.video.currentTextChanged.connect(self._choose)
        self.region.currentTextChanged.connect(self._choose)
        self._refresh_layers()
        napari_viewer.layers.events.inserted.connect(self._refresh_layers)
        napari_viewer.layers.events.removed.connect(self._refresh_layers)

    # -- the form
    def _refresh_layers(self, *_) -> None:
        """List the layers again, keeping the chosen ones chosen (under a new name too)."""
        for layer in self.viewer.layers:  # a renamed layer is listed under its new name
            if id(layer) not in self._watched:
                self._watched.add(id(layer))
                layer.events.name.connect(self._refresh_layers)
        chosen = {box: self._chosen.get(box) for box in (self.video, self.region)}
        self._listing = True
        self.video.clear()
        self.region.clear()
        self.region.addItem("(central 70 % of the frame)")
        for layer in self.viewer.layers:
            kind = type(layer).__name__
            if kind == "Image" and layer.metadata.get("source"):
                self.video.addItem(layer.name)
            elif kind in ("Shapes", "Labels"):
                self.region.addItem(layer.name)
        for box, layer in chosen.items():
            if layer is not None and layer in self.viewer.layers:
                box.setCurrentText(layer.name)
        self._listing = False
        self._choose()

    def _choose(self, *_) -> None:
        """Remember the layers chosen (the objects: their names may change)."""
        if self._listing:
            return
        for box in (self.video, self.region):
            name = box.currentText()
            self._chosen[box] = self.viewer.layers[name] if name in self.viewer.layers else None

    def _tracker_options(self, name: str) -> None:
        import inspect

        while self.options_form.rowCount():
            self.options_form.removeRow(0)
        self.option_fields = {}
        spec = self.trackers.get(name)
        if spec is None:
            return
        for option in spec.options:
            if option.is_file:
                continue  # files of other tools: from the command line
            parameter = inspect.signature(spec.function).parameters.get(option.name)
            default = None if parameter is None else parameter.default
            if default is inspect.Parameter.empty:
                default = None
            if option.switch is not None:  # ticked: the flag is given
                field = QCheckBox()
                field.setChecked(False)
            elif option.choices:
                field = QComboBox()
                field.addItems(list(option.choices))
                if default is not None:
                    field.setCurrentText(str(default))
            else:
                field = QLineEdit("" if default is None else str(default))
            field.setToolTip(option.help)
            self.options_form.addRow(option.flag.lstrip("-"), field)
            self.option_fields[option.flag] = field

    # -- the inputs
    def source(self) -> str:
        typed = self.video_path.text().strip()
        if typed:
            path = Path(typed).expanduser()
            if not path.exists():
                raise InputError(f"no such video or folder: {path}")
            return str(path)
        return str(self._video_layer().metadata["source"])

    def _video_layer(self):
        name = self.video.currentText()
        if not name:
            raise InputError("open a video (File > Open) or give its path")
        if name not in self.viewer.layers:
            raise InputError(f"the video layer {name!r} is gone: choose the video again")
        return self.viewer.layers[name]

    def _frame_shape(self, source: str) -> tuple[int, int]:
        if not self.video_path.text().strip() and self.video.currentText():
            return tuple(self._video_layer().data.shape[-2:])
        from strain2d import open_frames

        return tuple(open_frames([source], min_frames=1).shape)

    def drawn_region(self, shape: tuple[int, int]):
        """What the region layer says, in the video's pixels: ``None`` (the default
        region), ``("roi", (x0, y0, x1, y1))`` for one upright rectangle, ``("polygon",
        (K, 2) x, y)`` for one other closed shape, or ``("mask", (H, W) bool)`` for a
        labels layer (painted on any frame) or several shapes (their union)."""
        from tissue_core.masks import polygon_inside

        name = self.region.currentText()
        if not name or name == self.region.itemText(0):
            return None
        if name not in self.viewer.layers:
            raise InputError(f"the region layer {name!r} is gone: choose the region again")
        layer = self.viewer.layers[name]
        if type(layer).__name__ == "Labels":
            data = np.asarray(layer.data) > 0
            mask = data.any(axis=0) if data.ndim == 3 else data
            if mask.shape != shape or not mask.any():
                raise InputError(f"the labels layer {name!r} holds no tissue on a {shape} frame")
            return "mask", mask
        if not len(layer.data):
            raise InputError(f"draw the region on the shapes layer {name!r} first")
        shapes = []
        for vertices, kind in zip(layer.data, layer.shape_type, strict=True):
            if kind in ("line", "path"):
                raise InputError(f"a {kind} on {name!r} encloses no region: draw a closed shape")
            yx = self._pixels(layer, np.asarray(vertices, float))
            if kind == "ellipse":  # inscribed in its box (four corners, maybe turned)
                a = np.linspace(0, 2 * np.pi, 72, endpoint=False)[:, None]
                u, v = (yx[1] - yx[0]) / 2, (yx[2] - yx[1]) / 2  # the semi-axes
                yx = yx.mean(axis=0) + np.cos(a) * u + np.sin(a) * v
            shapes.append((kind, yx))
        if len(shapes) == 1:
            kind, yx = shapes[0]
            sides = [len(np.unique(yx[:, k].round(6))) for k in (0, 1)]
            upright = sides == [2, 2]
            if kind == "rectangle" and upright:
                (y0, x0), (y1, x1) = yx.min(axis=0), yx.max(axis=0)
                return "roi", (x0, y0, x1, y1)
            return "polygon", yx[:, ::-1]
        mask = np.zeros(shape, bool)
        for _, yx in shapes:
            mask |= polygon_inside(yx[:, ::-1], shape)
        return "mask", mask

    def _pixels(self, layer, vertices: np.ndarray) -> np.ndarray:
        """A shape's vertices in the video's pixels (y, x): through the world coordinates,
        so a shape drawn on a scaled or moved layer lands where it is seen."""
        world = np.array([layer.data_to_world(v) for v in vertices])
        if not self.video_path.text().strip() and self.video.currentText():
            video = self._video_layer()
            pixels = np.array([video.world_to_data(w) for w in world])
        else:
            pixels = world
        return pixels[:, -2:]

    def _region_args(self, out: Path, shape: tuple[int, int]) -> list[str]:
        """``--roi`` from an upright rectangle; ``--mask`` from any other region, written
        beside the output folder (``OUT_region.csv``, ``OUT_mask.png``) once the run's
        inputs are all good (removed again if the run does not end in results)."""
        region = self.drawn_region(shape)
        if region is None:
            return []
        kind, value = region
        if kind == "roi":
            x0, y0, x1, y1 = value
            return ["--roi", f"{x0:.1f},{y0:.1f},{x1:.1f},{y1:.1f}"]
        overwrite = self.overwrite.isChecked()
        if kind == "polygon":
            path = out.parent / f"{out.name}_region.csv"
            self._pending.append((path, lambda: _write_polygon(path, value, overwrite)))
        else:
            path = out.parent / f"{out.name}_mask.png"
            image = value.astype(np.uint8) * 255
            self._pending.append((path, lambda: _write_png(path, image, overwrite)))
        return ["--mask", str(path)]

    def command(self) -> list[str]:
        from strain2d import parse_grid

        source = self.source()
        out = self.output()
        parse_grid(self.grid.text().strip())  # its own message when malformed
        argv = ["strain2d", "analyze", source, "--grid", self.grid.text().strip()]
        argv += self._region_args(out, self._frame_shape(source))
        tracker = self.tracker.currentText()
        argv += ["--tracker", tracker]
        spec = self.trackers[tracker]
        for option in spec.options:
            field = self.option_fields.get(option.flag)
            if field is None:
                continue
            if isinstance(field, QCheckBox):
                if field.isChecked():
                    argv.append(option.flag)
                continue
            text = field.currentText() if isinstance(field, QComboBox) else field.text().strip()
            if text:
                option.convert(text, tracker)  # a bad value's message, before the run
                argv += [option.flag, text]
        if self.scale.text().strip():
            argv += ["--scale", self.scale.text().strip()]
        if self.fps.text().strip():
            argv += ["--fps", self.fps.text().strip()]
        argv += ["--out", str(out)]
        if self.overwrite.isChecked():
            argv.append("--overwrite")
        return argv

    # -- preview and results
    def preview(self) -> None:
        """The grid the run will track, as a points layer on the first frame."""
        from strain2d import default_roi, make_grid, masked_grid, parse_grid
        from tissue_core.masks import Mask, polygon_inside

        try:
            source = self.source()
            shape = self._frame_shape(source)
            grid = parse_grid(self.grid.text().strip())
            region = self.drawn_region(shape)  # nothing is written for a preview
            if region is None or region[0] == "roi":
                roi = default_roi(shape) if region is None else region[1]
                points = make_grid(shape, shape=grid, roi=roi)
            else:
                kind, value = region
                inside = polygon_inside(value, shape) if kind == "polygon" else value
                mask = Mask(inside=inside, source=f"the region layer {self.region.currentText()}",
                            kind="image")  # fmt: skip
                points, _, _ = masked_grid(shape, mask, shape=grid)
        except (InputError, OSError, ValueError) as exc:
            self.say(str(exc), error=True)
            return
        data = points[:, ::-1]
        name = "grid preview"
        if name in self.viewer.layers:
            self.viewer.layers[name].data = data
        else:
            self.viewer.add_points(data, name=name, size=8, face_color="yellow")
        self.say(f"{len(points)} points")

    def load(self, folder: Path) -> list:
        from tissue_napari.readers import strain_layers

        return add_layers(self.viewer, strain_layers(folder, self.component.currentText()))


class MpmWidget(_RunWidget):
    """The folds of a multiphoton z-stack (or a mosaic's tile list): ``mpm3d analyze`` in
    the background, then the height map and the surface in um, the crests, and the
    metrics in a table."""

    #: the metrics the table shows, with their units
    SHOWN = (
        ("fold_wavelength_um", "fold wavelength (um)"),
        ("fold_height_um", "median fold height (um)"),
        ("max_fold_height_um", "max fold height (um)"),
        ("n_folds", "folds"),
        ("fold_orientation_deg", "crest orientation (deg)"),
        ("fold_coherency", "coherency"),
        ("Sa_um", "Sa (um)"),
        ("Sq_um", "Sq (um)"),
        ("Sdr_percent", "Sdr (%)"),
        ("surface_coverage", "surface coverage"),
    )

    def __init__(self, napari_viewer) -> None:
        super().__init__(napari_viewer)
        self.stack = QLineEdit()
        self.stack.setPlaceholderText("z-stack .tif, or a mosaic's tiles.csv")
        self.memory = QLineEdit()
        self.memory.setPlaceholderText("e.g. 1.5GiB (default: half the memory available)")
        self.table = QTableWidget(0, 2)
        self.table.setHorizontalHeaderLabels(["metric", "value"])
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.verticalHeader().setVisible(False)
        self.table.setMinimumHeight(330)
        self.form.addRow("stack", _path_row(self.stack, folder=False))
        self.form.addRow("memory limit", self.memory)
        self._finish_layout([], below=[self.table])

    def command(self) -> list[str]:
        text = self.stack.text().strip()
        if not text:
            raise InputError("give a z-stack (.tif) or a mosaic's tile list (.csv)")
        path = Path(text).expanduser()
        if not path.is_file():
            raise InputError(f"no such stack: {path}")
        argv = ["mpm3d", "analyze", str(path), "--out", str(self.output())]
        if self.memory.text().strip():
            from mpm3d import parse_memory

            parse_memory(self.memory.text().strip())
            argv += ["--memory-limit", self.memory.text().strip()]
        if self.overwrite.isChecked():
            argv.append("--overwrite")
        return argv

    def load(self, folder: Path) -> list:
        from tissue_napari.readers import mpm3d_layers

        layers = mpm3d_layers(folder)
        metrics = layers[0][1]["metadata"]["metrics"]
        self.table.setRowCount(0)
        for key, label in self.SHOWN:
            value = metrics.get(key)
            row = self.table.rowCount()
            self.table.insertRow(row)
            self.table.setItem(row, 0, QTableWidgetItem(label))
            shown = (
                "-"
                if value is None
                else (f"{value:.4g}" if isinstance(value, float) else str(value))
            )
            self.table.setItem(row, 1, QTableWidgetItem(shown))
        return add_layers(self.viewer, layers)


def _write_png(path: Path, image: np.ndarray, overwrite: bool) -> None:
    import imageio.v3 as iio

    from tissue_core.outputs import atomic_file

    with atomic_file(path, overwrite=overwrite, option="the region's mask") as tmp:
        iio.imwrite(tmp, image, extension=".png")


def _write_polygon(path: Path, xy: np.ndarray, overwrite: bool) -> None:
    from tissue_core.csvtext import csv_writer
    from tissue_core.outputs import atomic_file

    with atomic_file(path, overwrite=overwrite, option="the region's polygon") as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            writer = csv_writer(f)
            writer.writerow(["x", "y"])
            writer.writerows([(f"{x:.2f}", f"{y:.2f}") for x, y in xy])


def run_numbers(summary: dict) -> list[tuple[str, str]]:
    """The headline numbers of a run's ``summary.json`` (or an mpm3d ``metrics.json``),
    as (what, value) rows: what its report opens with."""
    rows: list[tuple[str, str]] = []

    def number(value, digits: int = 4) -> str:
        return "-" if value is None else (f"{value:.{digits}g}" if isinstance(value, float)
                                          else str(value))  # fmt: skip

    if "fold_wavelength_um" in summary:  # mpm3d
        for key, label in MpmWidget.SHOWN:
            rows.append((label, number(summary.get(key))))
        return rows
    tracker = summary.get("tracker") or {}
    points = summary.get("points") or {}
    rows.append(("tracker", str(tracker.get("name", "-"))))
    rows.append(("points", number(points.get("n"))))
    rows.append(("points lost on the last frame", number(summary.get("lost_points_last_frame"))))
    sigma = (summary.get("tracking_uncertainty_px") or {}).get("median")
    rows.append(("median uncertainty (px)", number(sigma)))
    endpoint = summary.get("contraction_endpoint") or {}
    rows.append(
        ("endpoint frame", f"{number(endpoint.get('frame'))} ({endpoint.get('label', '')})")
    )
    final = (summary.get("statistics") or {}).get("nodal_strain") or {}
    for component in ("Exx", "Eyy", "Exy", "E1", "E2"):
        stats = final.get(component)
        if stats:
            spread = number(stats.get("sd"), 2)
            rows.append((f"{component} at the endpoint, mean (SD)",
                         f"{number(stats.get('mean'))} ({spread})"))  # fmt: skip
    for flag in summary.get("flags") or []:
        rows.append(("flag", str(flag)))
    return rows


class RunNumbersWidget(QWidget):
    """The headline numbers of the run behind the selected layer (its report's)."""

    def __init__(self, napari_viewer) -> None:
        super().__init__()
        self.viewer = napari_viewer
        self.title = QLabel("select a layer of a run folder")
        self.title.setWordWrap(True)
        self.table = QTableWidget(0, 2)
        self.table.setHorizontalHeaderLabels(["", "value"])
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.horizontalHeader().setSectionResizeMode(0, QHeaderView.ResizeToContents)
        self.table.setWordWrap(True)
        self.table.verticalHeader().setVisible(False)
        layout = QVBoxLayout(self)
        layout.addWidget(self.title)
        layout.addWidget(self.table)
        napari_viewer.layers.selection.events.active.connect(self.show_active)
        self.show_active()

    def show_active(self, *_) -> None:
        layer = self.viewer.layers.selection.active
        meta = getattr(layer, "metadata", {}) or {}
        summary = meta.get("summary") or meta.get("metrics")
        self.table.setRowCount(0)
        if not summary:
            self.title.setText("select a layer of a run folder")
            return
        self.title.setText(str(meta.get("run", "")))
        for what, value in run_numbers(summary):
            row = self.table.rowCount()
            self.table.insertRow(row)
            self.table.setItem(row, 0, QTableWidgetItem(what))
            self.table.setItem(row, 1, QTableWidgetItem(value))
