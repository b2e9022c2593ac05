from tissue_core.cli import run_module

run_module("mpm3d.cli")
