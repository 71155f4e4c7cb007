"""`python -m twinfleet.agreement experiment SCENARIO... [options]` (a bare SCENARIO means `experiment`)."""

from __future__ import annotations

import sys

from twinfleet.agreement.commands import main

sys.exit(main())
