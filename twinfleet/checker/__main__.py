"""`python -m twinfleet.checker SCENARIO [options]` (or `check ...` / `replay TRACE`)."""

from __future__ import annotations

import sys

from twinfleet.checker.commands import main

sys.exit(main())
