import os

# Never open windows or pick an interactive backend in tests.
os.environ.setdefault("MPLBACKEND", "Agg")
