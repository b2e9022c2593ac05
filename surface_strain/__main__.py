import sys

from surface_strain.cli import main

sys.exit(main())
