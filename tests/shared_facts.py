"""``../shared/FACTS.md``, the public figures the robot and walk tests check footsim against.  It sits
beside the repository, not in it: where it is absent (a clone on its own) those tests are skipped
with the reason, except under ``.ci/run`` (``FOOTSIM_REQUIRE_SHARED=1``), where they fail."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

FACTS = Path(__file__).resolve().parents[1].parent / "shared" / "FACTS.md"


def facts_text() -> str:
    """FACTS.md's text, or skip (fail under ``FOOTSIM_REQUIRE_SHARED=1``) the test that needs it."""
    if not FACTS.is_file():
        reason = f"{FACTS} is absent (the shared facts file sits beside the repository)"
        if os.environ.get("FOOTSIM_REQUIRE_SHARED") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    return FACTS.read_text()
