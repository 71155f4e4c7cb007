"""Python code run in a fresh interpreter (nothing generated yet, nothing imported)."""

from __future__ import annotations

import subprocess
import sys

from tests.support import ROOT


def run_python(code: str, stdin: bytes | None = None) -> subprocess.CompletedProcess[bytes]:
    """Run `code` with ``python -P -c`` in the checkout, `stdin` as its input; 60 s at most."""
    return subprocess.run([sys.executable, "-P", "-c", code], input=stdin, capture_output=True,
                          cwd=ROOT, timeout=60, check=False)
