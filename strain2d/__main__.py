from tissue_core.main import run

run("strain2d")
