import math
from pathlib import Path

import pytest

SPEC = Path(__file__).resolve().parents[1].parent / "shared" / "spec"


@pytest.fixture(scope="session")
def spec_dir():
    if not SPEC.is_dir():
        pytest.skip("../shared/spec not present")
    return SPEC


def pose_from_errors(ref_row, e1, e2, e3):
    """The robot pose whose tracking errors against ``ref_row`` are (e1, e2, e3)."""
    theta = ref_row[7] - e3
    c, s = math.cos(theta), math.sin(theta)
    return ref_row[1] - (c * e1 - s * e2), ref_row[2] - (s * e1 + c * e2), theta
