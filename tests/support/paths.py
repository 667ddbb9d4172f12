"""Where the repository's files are, for tests that read them."""

from __future__ import annotations

from pathlib import Path

#: the repository's root
REPO = Path(__file__).resolve().parents[2]
#: the paper's examples as case files
CASES = REPO / "config" / "cases"
