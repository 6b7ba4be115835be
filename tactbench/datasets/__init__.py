"""Built-in datasets, registered through the same hook as third-party ones.

This module only *describes* datasets (it stays light: no numpy at import
time); each is imported when it is built. Load any dataset by name or path with
:func:`tactbench.datasets.loading.load_dataset`.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_datasets(register):
    register("synthetic-forearm", "tactbench.datasets.synthetic_forearm:SyntheticForearm",
             summary="simulated 5-gesture study on a 1558-taxel forearm (1900 samples); "
                     "people=per-run: new simulated people every run (docs/simulator.md)")
    register("cyskin-text", "tactbench.datasets.cyskin_text:CySkinText",
             summary="CySkin acquisition text files; path=FOLDER|FILE")
    register("cost", "tactbench.datasets.cost:CoST",
             summary="Corpus of Social Touch, the CSV as distributed (31 subjects, 14 "
                     "gestures, 8x8, 135 Hz; variant an attribute); path=FILE "
                     "(docs/datasets.md)")
    register("haart", "tactbench.datasets.haart:HAART",
             summary="HAART challenge files training.csv + testWITHLABELS.csv (7 gestures, "
                     "8x8, 54 Hz; substrate, cover, set=training|test); path=FOLDER "
                     "(docs/datasets.md)")
    register("folder", "tactbench.datasets.folder:FolderDataset",
             summary="your own data: ROOT/<class>/<recording>.npy|.npz|.csv, (T,H,W) grids "
                     "or (T,N) taxel vectors; path=ROOT (see docs/own-data.md)")
