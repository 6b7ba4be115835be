"""Built-in classifiers, registered through the same hook as third-party ones.

This module only *describes* classifiers (no torch import); each is imported
when it is built. The contract is :data:`tactbench.contracts.CLASSIFIER`; saved
models are read with :func:`tactbench.classifiers.io.load_model`.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_classifiers(register):
    register("cnn-lstm", "tactbench.classifiers.models:CnnLstm",
             summary="the study's model: EfficientNet-B0 per frame → LSTM → FC 256 (GPU-sized)",
             requires=("torch",))
    register("small-cnn-lstm", "tactbench.classifiers.models:SmallCnnLstm",
             summary="CPU-sized CNN (4 conv blocks) per frame → LSTM → FC 256; quick default",
             requires=("torch",))
    register("taxel-lstm", "tactbench.classifiers.models:TaxelLstm",
             summary="taxel vectors without a layout: per-frame MLP → LSTM → FC 256",
             requires=("torch",))
    register("logreg", "tactbench.classifiers.classical:PooledLogReg",
             summary="floor: logistic regression on pooled per-frame statistics",
             requires=("torch",))
    register("sklearn", "tactbench.classifiers.sklearn:SklearnClassifier",
             summary="any scikit-learn classifier on pooled per-frame features: "
                     "estimator=NAME and its parameters (optional extra 'sklearn')",
             requires=("sklearn",))
