"""Old import paths keep working for one release: same module object, with a warning."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from tactbench._compat import MOVED_MODULES, MOVED_NAMES


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_old_path_is_the_new_module_and_warns(old):
    new = MOVED_MODULES[old]
    # A fresh interpreter: in this one the alias may already be in sys.modules.
    code = (f"import warnings; warnings.simplefilter('error')\n"
            f"try:\n    import {old}\nexcept DeprecationWarning as w:\n    print('warned', w)\n"
            f"warnings.simplefilter('ignore')\n"
            f"import {old} as a, {new} as b\nprint('same', a is b)\n"
            f"print('spec', b.__spec__.name, b.__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert f"warned {old} moved to {new}" in out
    assert "same True" in out
    assert f"spec {new} {new}" in out  # the module keeps its own identity


def test_every_new_home_exists_and_no_file_is_left_at_the_old_place():
    import tactbench

    root = Path(tactbench.__file__).parent
    for old, new in MOVED_MODULES.items():
        assert importlib.util.find_spec(new) is not None, new
        assert not (root / (old.split(".")[-1] + ".py")).exists(), old


def test_unknown_names_are_not_answered_by_the_alias_finder():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("tactbench.no_such_module")


def test_testing_face_exposes_both_conformance_suites():
    import tactbench.testing as face
    from tactbench.classifiers.testing import check_classifier
    from tactbench.encoders.testing import check_encoder

    assert face.check_encoder is check_encoder
    assert face.check_classifier is check_classifier


@pytest.mark.parametrize("module, name", sorted(MOVED_NAMES))
def test_a_name_that_left_a_split_module_is_found_there_with_a_warning(module, name):
    new = importlib.import_module(MOVED_NAMES[(module, name)])
    old = importlib.import_module(module)
    with pytest.warns(DeprecationWarning, match=f"{module}.{name} moved to"):
        assert getattr(old, name) is getattr(new, name)
    assert not hasattr(old, "no_such_name")
