from tissue_core.main import run

run("sample_data_synth")
