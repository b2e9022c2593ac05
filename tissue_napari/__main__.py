"""``python -m tissue_napari [PATH ...]``: napari with the plugin's widgets docked,
and the paths given opened with this plugin's readers."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    import napari

    argv = sys.argv[1:] if argv is None else argv
    viewer = napari.Viewer(title="tissue-strain")
    viewer.window.add_plugin_dock_widget("tissue-strain", "Strain from video")
    viewer.window.add_plugin_dock_widget("tissue-strain", "MPM folds")
    viewer.window.add_plugin_dock_widget("tissue-strain", "Run numbers")
    for path in argv:
        viewer.open(path, plugin="tissue-strain")
    napari.run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
