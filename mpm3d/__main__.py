import sys

from mpm3d.cli import main

sys.exit(main())
