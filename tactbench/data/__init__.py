"""The data stage: from taxel readings to tactile images and training windows.

==================  ========================================================================
module              what it holds
==================  ========================================================================
``recording``       ``Recording`` (values ``(T, N)``, timestamps, taxel ids), ``Frame``,
                    ``Sample`` (a labelled recording)
``normalisation``   ``Normalisation``: raw values → pressure in [0, 1] (``fixed``,
                    ``baseline``)
``dataset``         ``Dataset``: samples, classes, layout, normalisation; vectors, images,
                    content hash
``store``           the dataset folder on disk (``manifest.json`` + ``arrays.npz``):
                    ``write_dataset``, ``read_dataset_fields``
``layout``          ``TaxelLayout`` (taxel ids and positions in mm, image bounds),
                    ``unroll``
``layout_io``       layout files (CySkin JSON, CSV): ``load_layout``; the layout ↔ dict
                    format: ``layout_to_dict``, ``layout_from_dict``
``imaging``         ``Imager`` (imaging Φ: taxel values → images), ``image_shape``
``preview``         ``preview_strip``: one sample as a picture (``tactbench data preview``)
``splits``          what a split yields (``Split``: train/test indices, fold and group
                    ids), the built-in designs (``paper``, ``users``, ``group``, ``kfold``),
                    the checks of every draw (``draw_splits``: its design, its groups)
``windows``         windows of L frames for training and testing
``strategies``      the built-in splits and test windows as the small objects the hooks
                    ``register_splits`` and ``register_test_windows`` register (below)
``sklearn_splits``  ``sklearn:NAME``: any scikit-learn splitter as a split (``GroupKFold``,
                    ``LeaveOneGroupOut``, ...), its design following from the splitter
==================  ========================================================================

Datasets themselves (the simulator, file formats, the generated forearm) are in
:mod:`tactbench.datasets`. Nothing here imports a heavy library at import time. This
module is a built-in plugin: it registers the splits and test windows, by name, the way
plugins register theirs.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_splits(register):
    register("paper", "tactbench.data.strategies:PaperSplit",
             summary="test_per_class random recordings of each class (the study's)")
    register("users", "tactbench.data.strategies:UsersSplit",
             summary="leave a random fifth of the users out; folds=K: K-fold over users")
    register("group", "tactbench.data.strategies:GroupSplit",
             summary="group:KEY leaves recording metadata out (position, repetition): "
                     "a fifth, folds=K or test=A|B")
    register("kfold", "tactbench.data.strategies:KFoldSplit",
             summary="kfold:folds=K: stratified K-fold over recordings, repeated over "
                     "seeds (each recording tested once per run)")
    register("sklearn", "tactbench.data.sklearn_splits:SklearnSplit",
             summary="sklearn:NAME[:options]: any scikit-learn splitter (GroupKFold, "
                     "LeaveOneGroupOut, StratifiedKFold, ...), groups=KEY for the group "
                     "ones (optional extra 'sklearn')",
             requires=("sklearn",))


@hookimpl
def register_test_windows(register):
    register("vote", "tactbench.data.strategies:VoteWindow",
             summary="every window of a test recording, probabilities averaged")
    register("first", "tactbench.data.strategies:FirstWindow",
             summary="the first L frames of a test recording (the study's)")
    register("onset", "tactbench.data.strategies:OnsetWindow",
             summary="the L frames from a test recording's contact onset")
