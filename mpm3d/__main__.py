from tissue_core.main import run

run("mpm3d")
