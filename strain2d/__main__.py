import sys

from strain2d.cli import main

sys.exit(main())
