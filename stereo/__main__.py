from tissue_core.main import run

run("stereo")
