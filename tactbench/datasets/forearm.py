"""The generated CySkin-like forearm of the study: triangular modules on a cylinder.

:func:`cyskin_forearm` builds the :class:`~tactbench.data.layout.TaxelLayout` that the
``synthetic-forearm`` dataset (:mod:`tactbench.datasets.synthetic`) is simulated on and
that ``tactbench layout generate`` writes.
"""

from __future__ import annotations

import math

import numpy as np

from tactbench.data.layout import SLOTS_PER_ID, TaxelLayout
from tactbench.errors import InputError, check_positive_float, check_positive_int

#: Slot positions of a CySkin-like triangular module in lattice coordinates
#: (i, j): the 12 points on the perimeter of a triangle 4 pitches (30 mm) a side.
_MODULE_SLOTS = [(i, j) for j in range(5) for i in range(5 - j)
                 if i == 0 or j == 0 or i + j == 4]
#: The slot that carries no taxel (CySkin modules: 12 slots, up to 11 taxels).
_EMPTY_SLOT = 11


def cyskin_forearm(n_taxels: int = 1558, *, circumference_mm: float = 334.0,
                   length_mm: float = 357.0, pitch_mm: float = 7.5,
                   module_side_mm: float = 44.0, seed: int = 0) -> TaxelLayout:
    """A CySkin-like forearm: triangular modules on a cylinder, unrolled.

    The cylinder's circumference (``x``) and length (``y``) give the sheet
    ``bounds = (0, 0, circumference_mm, length_mm)``; with the defaults the image
    at 1 mm per pixel is 357 × 334 (rows × columns), as in the study.

    Modules are triangles (alternately pointing up and down) laid in rows
    along the axis; each has 12 slots on a triangular lattice of ``pitch_mm``
    (the perimeter of a triangle 4 pitches a side) of which 11 carry taxels
    (slot 11 is empty, as a temperature sensor's would be). With the default
    ``module_side_mm`` neighbouring modules continue the same lattice, so the
    skin has no gaps wider than two pitches apart from the underside strip. Module
    rows and columns are spread evenly over the sheet (nominal triangle side
    ``module_side_mm``); the columns wrap around the cylinder. When fewer
    taxels are asked for than modules hold, the modules farthest from the top
    of the arm (``x = circumference / 2``, so starting on the underside, where
    a cable channel would run) are left out, then the remaining surplus
    taxels (4 for the default 1558) are dropped at random (``seed``), like the
    unpopulated slots of a real skin.

    Ids are ``module_id * 16 + slot`` with module ids from 1. ``positions_3d``
    and ``normals`` describe the cylinder (axis along ``y``).
    """
    n_taxels = check_positive_int(n_taxels, "n_taxels")
    for value, name in ((circumference_mm, "circumference_mm"), (length_mm, "length_mm"),
                        (pitch_mm, "pitch_mm"), (module_side_mm, "module_side_mm")):
        check_positive_float(value, name)
    per_module = len(_MODULE_SLOTS) - 1
    row_h = module_side_mm * math.sqrt(3) / 2
    n_rows = max(1, round(length_mm / row_h))
    n_cols = max(2, 2 * round(circumference_mm / module_side_mm))
    step_x = circumference_mm / n_cols  # half a triangle side
    step_y = length_mm / n_rows
    n_modules = math.ceil(n_taxels / per_module)
    if n_modules > n_rows * n_cols:
        raise InputError(f"{n_taxels} taxels need {n_modules} modules, but a "
                         f"{circumference_mm} x {length_mm} mm sheet holds {n_rows * n_cols}")
    # module centres and orientation (up/down alternate along a row and between rows)
    rr, cc = np.meshgrid(np.arange(n_rows), np.arange(n_cols), indexing="ij")
    rr, cc = rr.ravel(), cc.ravel()
    up = (rr + cc) % 2 == 0
    cx = (cc + 0.5) * step_x
    cy = (rr + 0.5) * step_y + np.where(up, -1.0, 1.0) * step_y / 6  # centroids
    # keep the modules nearest the top of the arm (x = C/2), row by row outwards
    around = np.abs(cx - circumference_mm / 2)
    order = np.lexsort((np.abs(cy - length_mm / 2), around))
    keep = np.sort(order[:n_modules])
    # slot offsets from a module's centroid (pointing up; flip y for down)
    lat = np.array([(i + j / 2, j * math.sqrt(3) / 2) for i, j in _MODULE_SLOTS]) * pitch_mm
    lat -= np.array([2.0, 2 / math.sqrt(3)]) * pitch_mm  # centroid of the 4-pitch triangle
    slots = np.array([s for s in range(len(_MODULE_SLOTS)) if s != _EMPTY_SLOT])
    ids, xs, ys = [], [], []
    for module_id, m in enumerate(keep, start=1):
        off = lat[slots].copy()
        if not up[m]:
            off[:, 1] *= -1
        ids.append(module_id * SLOTS_PER_ID + slots)
        xs.append(cx[m] + off[:, 0])
        ys.append(cy[m] + off[:, 1])
    ids_a = np.concatenate(ids)
    pos = np.column_stack([np.concatenate(xs) % circumference_mm, np.concatenate(ys)])
    surplus = ids_a.size - n_taxels
    if surplus > 0:
        rng = np.random.default_rng(seed)
        drop = rng.choice(ids_a.size, size=surplus, replace=False)
        mask = np.ones(ids_a.size, dtype=bool)
        mask[drop] = False
        ids_a, pos = ids_a[mask], pos[mask]
    radius = circumference_mm / (2 * math.pi)
    theta = pos[:, 0] / radius
    normals = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    p3 = np.column_stack([radius * normals[:, 0], radius * normals[:, 1], pos[:, 1]])
    return TaxelLayout(ids=ids_a, positions=pos, positions_3d=p3, normals=normals,
                       bounds=(0.0, 0.0, float(circumference_mm), float(length_mm)),
                       name=f"cyskin-forearm-{n_taxels}")
