import sys

print(
    "stereo: not implemented yet in this version (planned: calibrate, match, reconstruct)",
    file=sys.stderr,
)
sys.exit(2)
