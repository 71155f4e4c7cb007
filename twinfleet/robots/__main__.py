"""`python -m twinfleet.robots experiment SCENARIO... [options]` (a bare SCENARIO means `experiment`)."""

from __future__ import annotations

import sys

from twinfleet.robots.commands import main

sys.exit(main())
