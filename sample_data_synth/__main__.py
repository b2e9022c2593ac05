import sys

from sample_data_synth.cli import main

sys.exit(main())
