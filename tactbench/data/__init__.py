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
``splits``          train/test splits (``paper``, ``users``)
``windows``         windows of L frames for training and testing
==================  ========================================================================

Datasets themselves (the simulator, file formats, the generated forearm) are in
:mod:`tactbench.datasets`. Nothing here imports a heavy library at import time.
"""
