import sys

print("mpm3d: not implemented yet in this version (planned: analyze, compare)", file=sys.stderr)
sys.exit(2)
