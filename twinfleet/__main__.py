"""`python -m twinfleet ...`: the `twinfleet` command line."""

import sys

from twinfleet.cli import main

sys.exit(main())
