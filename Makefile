# Two commands for users (see README):  make demo   and   make test
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
DEMO   := demo_output
PACKAGES := tissue_core strain2d surface_strain stereo mpm3d multimodal sample_data_synth \
	tissue_napari
# Debian packages the core needs at run time (VTK's shared libraries); Chromium renders
# the reports in the tests (tests/test_report_browser.py); the napari plugin's tests draw
# with Qt in a virtual X display (Xvfb, Mesa's OpenGL, Qt's X libraries).
SYSTEM_LIBS := libgl1 libxrender1 libx11-6
QT_LIBS := xvfb libegl1 libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 \
	libxcb-shape0 libxcb-xinerama0 libfontconfig1 libdbus-1-3

.PHONY: setup demo test docs docs-check lint bench bench-pages bench-mpm3d accuracy system-deps setup-3d setup-torch clean

system-deps:
	@missing=""; \
	for lib in libGL.so.1 libXrender.so.1 libX11.so.6; do \
	  ldconfig -p | grep -q "$$lib" || missing="$$missing $$lib"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq $(SYSTEM_LIBS); \
	  else \
	    echo "missing system libraries:$$missing; install them with:"; \
	    echo "  sudo apt-get install -y $(SYSTEM_LIBS)"; exit 1; fi; fi
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq chromium; \
	  else \
	    echo "note: the report tests render report.html in Chromium; install it with:"; \
	    echo "  sudo apt-get install -y chromium"; fi
	@missing=""; command -v Xvfb >/dev/null || missing="$$missing Xvfb"; \
	for lib in libEGL.so.1 libxkbcommon-x11.so.0 libxcb-cursor.so.0 libfontconfig.so.1; do \
	  ldconfig -p | grep -q "$$lib" || missing="$$missing $$lib"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq $(QT_LIBS); \
	  else \
	    echo "missing for the napari plugin's tests:$$missing; install them with:"; \
	    echo "  sudo apt-get install -y $(QT_LIBS)"; exit 1; fi; fi
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "Python >= 3.11 is needed (set PYTHON=python3.11)"; exit 1; }
	@$(PYTHON) -c 'import venv, ensurepip' 2>/dev/null || \
	  { echo "Python's venv module is missing; install it with:"; \
	    echo "  sudo apt-get install -y python3-venv"; exit 1; }

# pip writes the libraries' bytecode, compileall the toolkit's: with PYTHONDONTWRITEBYTECODE
# set (as on CI machines) no process writes it, and every command and test worker compiled
# every module it imported again (a fresh clone's suite took 613 s against 455 s)
$(BIN)/.installed: pyproject.toml | system-deps
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	$(BIN)/python -m compileall -q $(PACKAGES) scripts > /dev/null
	$(BIN)/python scripts/compile_kernels.py  # numba's cache, once (not in every first process)
	touch $@

setup: $(BIN)/.installed

# The documentation site, offline, into site/ (warnings are errors; the API pages first).
docs: setup
	$(BIN)/python docs/gen_api.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict -d site
	@echo "documentation in site/index.html"

# Every command the guides and the README show, run as a user would (those that need
# the user's data, the demo's, a cluster or a display are marked so and only parsed).
docs-check: setup
	$(BIN)/python -m pytest -q -p no:cacheprovider -m guide_commands tests/test_docs.py

# Render a synthetic equibiaxial-stretch video (with ground truth) and analyze it.
demo: setup
	mkdir -p $(DEMO)
	$(BIN)/python -m sample_data_synth video --case equibiaxial --out $(DEMO)/data --overwrite
	$(BIN)/python -m strain2d analyze $(DEMO)/data/equibiaxial.avi --grid 7x7 \
	    --roi 202,202,597,597 --scale 0.012mm/px --fps 10 --out $(DEMO)/equibiaxial --overwrite
	@echo "demo results in $(DEMO)/equibiaxial: report.html, tracks.csv, strain_nodes.csv, strain.pvd, figures/"
	$(BIN)/python -m sample_data_synth twitches --out $(DEMO)/twitches --overwrite -q
	$(BIN)/python -m strain2d analyze $(DEMO)/twitches/twitches.avi --mask $(DEMO)/twitches/mask.png \
	    --grid 11x9 --fps 10 --maps-at peaks --out $(DEMO)/twitches/run --overwrite
	@echo "demo results in $(DEMO)/twitches/run: three twitches in a tissue mask (cycles.csv, figures/cycles.png)"
	$(BIN)/python -m sample_data_synth stack --case pair --out $(DEMO)/stacks --overwrite -q
	$(BIN)/python -m mpm3d analyze $(DEMO)/stacks/after.tif --out $(DEMO)/mpm3d_after --overwrite
	$(BIN)/python -m mpm3d compare $(DEMO)/stacks/before.tif $(DEMO)/stacks/after.tif \
	    --out $(DEMO)/mpm3d_compare --overwrite
	@echo "demo results in $(DEMO)/mpm3d_after (report.html, metrics.json, surface.vtp, figures/) and $(DEMO)/mpm3d_compare"
	$(BIN)/python -m sample_data_synth stereo --case calibration --out $(DEMO)/stereo_targets --overwrite -q
	$(BIN)/python -m sample_data_synth stereo --case dome --out $(DEMO)/stereo_scene --overwrite -q
	$(BIN)/python -m stereo calibrate --board checkerboard:9x6:10 \
	    --left "$(DEMO)/stereo_targets/calibration/left/*.png" \
	    --right "$(DEMO)/stereo_targets/calibration/right/*.png" \
	    --out $(DEMO)/stereo_calib.json --overwrite
	$(BIN)/python -m stereo reconstruct --calib $(DEMO)/stereo_calib.json \
	    --left $(DEMO)/stereo_scene/dome/left --right $(DEMO)/stereo_scene/dome/right \
	    --grid 13x13 --roi 525,318,664,456 --strain --out $(DEMO)/stereo_dome --overwrite
	@echo "demo results in $(DEMO)/stereo_calib.json and $(DEMO)/stereo_dome (report.html, points3d.csv, strain/, figures/)"
	$(BIN)/python -m sample_data_synth study --out $(DEMO)/study_data --overwrite -q
	$(BIN)/python -m strain2d batch $(DEMO)/study_data/manifest.csv --grid 7x7 --fps 10 \
	    --out $(DEMO)/study_batch --overwrite
	@echo "demo results in $(DEMO)/study_batch: runs/S*/report.html, study/report.html, batch.log"

test: setup
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n auto --dist loadgroup

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: setup
	mkdir -p bench/results
	$(BIN)/python -m strain2d benchmark --sweep grid,subset,noise,contrast,density \
	    --out bench/results/table1 --overwrite

# The bench scripts quick enough to rerun often, each writing its page in docs/bench/
# (bench/page.py; about 10 minutes on 2 cores). The long ones: python bench/page.py SCRIPT
BENCH_PAGES = bench_kinematics.py bench_klt.py bench_trackers.py \
	bench_icgn_threads.py bench_mosaic.py
bench-pages: setup
	for script in $(BENCH_PAGES); do $(BIN)/python bench/page.py $$script || exit 1; done
	$(BIN)/python bench/page.py bench_analyze.py --sheet --repeat 2
	$(BIN)/python bench/page.py bench_default_tracker.py --only speed,threads --trackers gdic,dic

# The demo's z-stack and stereo results against the synthetic truth (after make demo)
accuracy: setup
	$(BIN)/python bench/accuracy_demo.py

# mpm3d analyze against scikit-image's marching cubes on a 240 x 1024 x 1024 stack (~2 min)
bench-mpm3d: setup
	$(BIN)/python bench/bench_mpm3d.py | tee bench/results/mpm3d.md

# Optional extras: open3d needs the system library libusb-1.0-0.
setup-3d: setup
	@ldconfig -p | grep -q libusb-1.0.so.0 || { \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y -qq libusb-1.0-0; \
	  else echo "open3d needs libusb: sudo apt-get install -y libusb-1.0-0"; exit 1; fi; }
	$(BIN)/python -m pip install --quiet -e ".[3d]"

# PyTorch for the cotracker3 tracker (the dev tools that make setup installs include it);
# says which build is there: for a GPU, install the CUDA build from pytorch.org into .venv.
setup-torch: setup
	$(BIN)/python -m pip install --quiet -e ".[torch]"
	@$(BIN)/python -c "import torch; print('PyTorch', torch.__version__, \
	  '(CUDA device found)' if torch.cuda.is_available() else '(no CUDA device: CPU only)')"

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache .ruff_cache
