from tissue_core.cli import run_module

run_module("stereo.cli")
