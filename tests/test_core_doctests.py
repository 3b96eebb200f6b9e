import doctest

import pytest

import nonholo
import nonholo.expressions
import nonholo.references


@pytest.mark.parametrize("module", [nonholo, nonholo.expressions, nonholo.references], ids=lambda m: m.__name__)
def test_docstring_examples(module):
    failures, attempted = doctest.testmod(module)
    assert attempted > 0 and failures == 0
