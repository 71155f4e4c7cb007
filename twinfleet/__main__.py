"""`python -m twinfleet ...`: the `twinfleet` command line.

`python -m` puts the working directory first on `sys.path`; the console script and the
node processes (`python -P`) do not. It is dropped here, so that a user's modules resolve
the same way whichever way the command was started: the scenario file's folder, then the
working directory, both appended last (`runtime.scenario.spec.user_import_path`).
"""

import os
import sys

if sys.path and sys.path[0] in ("", os.getcwd()):
    del sys.path[0]

from twinfleet.cli import main  # noqa: E402 - after the path is set as the module docstring says

sys.exit(main())
