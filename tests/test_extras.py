"""Optional dependencies: a missing extra is a one-line error naming what installs it."""

from __future__ import annotations

import json

import pytest

from meshlab_sharp.errors import InputError
from meshlab_sharp.extras import require


def test_a_missing_extra_names_the_feature_and_the_extra():
    with pytest.raises(InputError) as info:
        require("no_such_package_here.sub", "reading XYZ", "xyz")
    expected = "reading XYZ needs no_such_package_here: pip install 'meshlab-sharp[xyz]'"
    assert str(info.value) == expected


def test_a_present_module_is_returned():
    assert require("json", "anything", "none") is json
