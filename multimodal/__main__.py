from tissue_core.main import run

run("multimodal")
