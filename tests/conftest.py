import math
from html.parser import HTMLParser
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


class ReportPage(HTMLParser):
    """What the report tests look at in an HTML page: images, outward links, section ids,
    the number of tables and the text."""

    def __init__(self, html: str):
        super().__init__()
        self.images, self.links, self.sections, self.tables, self.text = [], [], [], 0, []
        self.feed(html)
        self.close()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs["src"])
        elif tag == "a" and not attrs["href"].startswith("#"):
            self.links.append(attrs["href"])
        elif tag == "section":
            self.sections.append(attrs["id"])
        elif tag == "table":
            self.tables += 1

    def handle_data(self, data):
        self.text.append(data)
