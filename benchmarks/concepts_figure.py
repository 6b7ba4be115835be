"""The figure of docs/concepts.md: one simulated sample along the data's path.

    python benchmarks/concepts_figure.py [--out docs/img/concepts-path.png]

One ``Twist`` of the built-in simulator (``synthetic-forearm:users=2,repetitions=1``),
drawn with tactbench's own calls at each stage:

1. the taxel readings of one frame, normalised to [0, 1] (``Dataset.vectors``), at each
   taxel's position on the unrolled forearm (``TaxelLayout.positions``);
2. the same frame as a tactile image (Φ, ``Dataset.images(pixel_mm=5)``);
3. the Farnebäck encoding of the sequence (``farneback``: pressure, flow magnitude, flow
   direction), its magnitude and direction channels at that frame;
4. the window of L = 5 frames a classifier sees (the first five: the study's test window).

Deterministic (the simulator and Farnebäck are seeded/deterministic); a few seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SPEC = "synthetic-forearm:users=2,repetitions=1"
PIXEL_MM = 5.0
L = 5


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(REPO / "docs" / "img" / "concepts-path.png"))
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tactbench.datasets.loading import load_dataset
    from tactbench.plugins import load_registry

    ds = load_dataset(SPEC)
    index = next(i for i, s in enumerate(ds.samples) if ds.classes[s.label] == "Twist")
    sample = ds.samples[index]
    vectors = ds.vectors([index])[0]                       # (T, N) in [0, 1]
    images = ds.images(pixel_mm=PIXEL_MM, indices=[index])[0]   # (T, H, W) in [0, 1]
    encoder = load_registry().build("encoder", "farneback")
    encoded = encoder.encode(images)                       # (T, 3, H, W)
    frame = int(np.argmax(vectors.sum(axis=1)))            # the frame of peak pressure
    positions = ds.layout.positions[ds.layout.indices_of(sample.recording.taxel_ids)]

    fig = plt.figure(figsize=(14, 5.6), layout="constrained")
    top = fig.subfigures(2, 1, height_ratios=[1.35, 1])
    axes = top[0].subplots(1, 4)
    on = vectors[frame] > 0.02
    axes[0].scatter(positions[~on, 0], positions[~on, 1], s=1, c="0.85")
    axes[0].scatter(positions[on, 0], positions[on, 1], s=3, c=vectors[frame, on],
                    cmap="inferno", vmin=0, vmax=1)
    axes[0].set_title(f"1. taxel readings\n{len(positions)} taxels, frame {frame}, [0, 1]")
    axes[0].set_aspect("equal")
    axes[0].set_xlabel("mm round the arm")
    axes[0].set_ylabel("mm along the arm")
    axes[1].imshow(images[frame], cmap="inferno", vmin=0, vmax=1, origin="lower")
    axes[1].set_title(f"2. Φ: tactile image\n{images.shape[1]} × {images.shape[2]} px "
                      f"at {PIXEL_MM:g} mm")
    for ax, channel, cmap in ((axes[2], 1, "viridis"), (axes[3], 2, "twilight")):
        name = encoder.channels[channel]
        ax.imshow(encoded[frame, channel], cmap=cmap, origin="lower")
        ax.set_title(f"3. encoder farneback: {name}\n(channel {channel + 1} of "
                     f"{encoded.shape[1]}: {', '.join(encoder.channels)})", fontsize=10)
    for ax in axes[1:]:
        ax.set_xticks([])
        ax.set_yticks([])
    window = top[1].subplots(1, L)
    for t, ax in enumerate(window):
        ax.imshow(images[t], cmap="inferno", vmin=0, vmax=1, origin="lower")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"t = {t}", fontsize=9)
    top[1].suptitle(f"4. the window a classifier sees: L = {L} frames × "
                    f"{encoded.shape[1]} channels (here the pressure channel), "
                    f"label {ds.classes[sample.label]}", fontsize=10)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out} (sample {index}, {ds.classes[sample.label]}, frame {frame})")
    return out


if __name__ == "__main__":
    main()
