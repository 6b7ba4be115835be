"""The data stage: recordings and datasets, their on-disk store, taxel layouts and their
file formats, imaging Φ (taxel values → tactile images), splits and windows.

Nothing here imports a heavy library; numpy is the only numerical dependency.
"""
