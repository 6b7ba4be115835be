"""Old import paths keep working for one release: same module object, with a warning."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from tactbench._compat import MOVED_MODULES


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_old_path_is_the_new_module_and_warns(old):
    new = MOVED_MODULES[old]
    # A fresh interpreter: in this one the alias may already be in sys.modules.
    code = (f"import warnings; warnings.simplefilter('error')\n"
            f"try:\n    import {old}\nexcept DeprecationWarning as w:\n    print('warned', w)\n"
            f"warnings.simplefilter('ignore')\n"
            f"import {old} as a, {new} as b\nprint('same', a is b)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert f"warned {old} moved to {new}" in out
    assert "same True" in out


def test_every_alias_file_points_where_the_table_says():
    for old, new in MOVED_MODULES.items():
        assert importlib.util.find_spec(new) is not None, new
        spec = importlib.util.find_spec(old)
        assert spec is not None and spec.origin.endswith(old.split(".")[-1] + ".py")


def test_testing_face_exposes_both_conformance_suites():
    import tactbench.testing as face
    from tactbench.classifiers.testing import check_classifier
    from tactbench.encoders.testing import check_encoder

    assert face.check_encoder is check_encoder
    assert face.check_classifier is check_classifier
