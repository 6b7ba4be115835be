"""The ``contact-events`` encoder: where the skin is touched, and where touch begins or ends."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.base import Encoder, previous_frames


class ContactEvents(Encoder):
    """Pressure, a contact mask and contact onset/release events (3 channels).

    Parameters
    ----------
    threshold : float
        Pressure in (0, 1) above which a pixel counts as touched.
    """

    name = "contact-events"
    channels = ("pressure", "contact", "events")
    ranges = ((0.0, 1.0), (0.0, 1.0), (0.0, 1.0))

    def __init__(self, *, threshold: float = 0.05) -> None:
        if not 0.0 < float(threshold) < 1.0:
            raise ValueError(f"threshold must lie in (0, 1), got {threshold}")
        self.threshold = float(threshold)

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        contact = seq > self.threshold
        before = previous_frames(seq) > self.threshold  # nothing touches before frame 0
        out = np.empty((seq.shape[0], 3, *seq.shape[1:]), dtype=np.float32)
        out[:, 0] = seq
        out[:, 1] = contact
        # onset → 1, release → 0, no change → 0.5
        out[:, 2] = 0.5 + 0.5 * (contact.astype(np.float32) - before.astype(np.float32))
        return out
