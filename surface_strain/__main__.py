from tissue_core.main import run

run("surface_strain")
