from tissue_core.cli import run_module

run_module("sample_data_synth.cli")
