"""Run profiles, defined once in tactbench.profiles (imaging and classifier halves)."""

from __future__ import annotations

import pytest

from tactbench.plugins import load_registry
from tactbench.profiles import PROFILE_NAMES, profile_options

BUILTIN = ("small-cnn-lstm", "cnn-lstm", "taxel-lstm", "logreg")


def test_paper_profile_is_the_papers_protocol():
    opts = profile_options("paper", "cnn-lstm")
    assert opts["optimizer"] == "sgd" and opts["lr"] == 1e-3 and opts["epochs"] == 100
    assert opts["input_size"] == 224
    assert opts["windows_per_epoch"] == 0  # every training window, every epoch


#: What the quick profile's small-cnn-lstm changed from the class defaults (issue 28); the
#: class defaults stay the recipe of before, so a stored spec that leaves an option out
#: keeps the meaning it had when it was written.
QUICK_RECIPE = {"head": "concat", "input_size": 16, "windows_per_epoch": 24000,
                "optimizer": "adamw", "schedule": "onecycle", "weight_decay": 0.01}


def test_quick_is_the_default_and_differs_from_the_class_defaults_only_in_its_recipe():
    reg = load_registry()
    for name in BUILTIN:
        default = reg.build("classifier", name).options()
        quick = reg.build("classifier", name, **profile_options("quick", name)).options()
        changed = QUICK_RECIPE if name == "small-cnn-lstm" else {}
        assert quick == {**default, **changed}, name
        assert all(default.get(k) != v for k, v in changed.items()), name
    assert profile_options(classifier="small-cnn-lstm") == profile_options("quick",
                                                                           "small-cnn-lstm")


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("name", BUILTIN)
def test_every_profile_option_is_accepted_and_user_options_override(profile, name):
    opts = profile_options(profile, name)
    clf = load_registry().build("classifier", name, **opts)
    for key, value in opts.items():
        assert getattr(clf, key) == value
    if "epochs" in opts:
        opts["epochs"] = 1
        assert load_registry().build("classifier", name, **opts).epochs == 1


def test_profile_options_returns_a_fresh_dict():
    profile_options("quick", "small-cnn-lstm")["epochs"] = 999
    assert profile_options("quick", "small-cnn-lstm")["epochs"] != 999


def test_unknown_profile_or_classifier_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown profile 'fast'.*quick, paper"):
        profile_options("fast", "small-cnn-lstm")
    with pytest.raises(LookupError, match="unknown classifier"):
        profile_options("quick", "no-such-classifier")


def test_profiles_are_defined_once_in_tactbench_profiles():
    import tactbench.classifiers.training as training
    import tactbench.profiles as profiles

    # the old import path is the same function, not a copy
    assert training.profile_options is profiles.profile_options
    assert training.PROFILE_NAMES == profiles.PROFILE_NAMES == ("quick", "paper")
    assert [profiles.get_profile(n).pixel_mm for n in profiles.PROFILE_NAMES] == [5.0, 1.0]
    with pytest.raises(ValueError, match="unknown profile 'fast'.*quick, paper"):
        profiles.get_profile("fast")


def test_a_plugin_classifier_declares_its_own_profiles(tmp_path, monkeypatch):
    # read through the registry given (a plugin added without installing it)
    import tactbench
    from tactbench.plugins import collect_registry, make_plugin_manager

    (tmp_path / "profiled_clf.py").write_text(
        "from tactbench.classifiers.classical import PooledLogReg\n\n"
        "class Profiled(PooledLogReg):\n"
        "    profiles = {'paper': {'max_iter': 500}}\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    class Plugin:
        @tactbench.hookimpl
        def register_classifiers(self, register):
            register("profiled", "profiled_clf:Profiled", summary="declares profiles")
            register("plain", "tactbench.classifiers.classical:PooledLogReg",
                     summary="declares none")

    reg = collect_registry(make_plugin_manager(entry_points=False,
                                               extra=[("profiled", Plugin())]))
    assert profile_options("paper", "profiled", registry=reg) == {"max_iter": 500}
    assert profile_options("quick", "profiled", registry=reg) == {}
    assert profile_options("paper", "plain", registry=reg) == {}


def test_a_classifier_is_named_as_a_runs_cells_name_it():
    """canonical_classifier: resolved by the registry, the profile's options under the
    spec's own, sorted; the name benchmarks/training.py finds its recipes' cells by."""
    from tactbench.profiles import canonical_classifier, profile_options

    quick = profile_options("quick", "small-cnn-lstm")
    spec = canonical_classifier("small-cnn-lstm:width=8")
    assert spec.startswith("small-cnn-lstm:") and "width=8" in spec
    assert f"input_size={quick['input_size']}" in spec
    assert canonical_classifier("small-cnn-lstm:width=8") == \
        canonical_classifier("small-cnn-lstm:width=8,input_size=" + str(quick["input_size"]))
    assert canonical_classifier("sklearn:SVC") == "sklearn:estimator=SVC"
