"""``tactbench encode``: encode one sequence file with any registered encoder."""

from __future__ import annotations

import json
from pathlib import Path

import click

from tactbench.errors import InputError, MissingFileError


@click.command("encode")
@click.option("--encoder", "-e", "spec", required=True,
              help="Encoder name and options, e.g. 'farneback:winsize=9,levels=2'.")
@click.option("--input", "-i", "input_path", required=True, type=click.Path(dir_okay=False),
              help="A .npy file with a (T, H, W) sequence: float in [0, 1] or unsigned ints.")
@click.option("--out", "-o", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Where to write the float32 (T, C, H, W) .npy; metadata goes beside it "
                   "as .json.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def encode_cmd(spec: str, input_path: str, out_path: str, as_json: bool) -> None:
    """Encode a (T, H, W) sequence into (T, C, H, W) feature images.

    The metadata file (OUT with suffix .json) records the encoder, its version
    and options, the channel names and ranges, and for flow encoders the
    magnitude scale in pixels per frame.
    """
    import time

    import numpy as np

    from tactbench.cli import get_registry
    from tactbench.contracts import ENCODER
    from tactbench.paths import atomic_write_text

    src = Path(input_path)
    if not src.is_file():
        raise MissingFileError(f"{src}: no such file")
    try:
        seq = np.load(src, allow_pickle=False)
    except Exception as exc:  # numpy raises several types for a bad file
        raise InputError(f"{src}: not a readable .npy array ({type(exc).__name__}: {exc})")
    if not isinstance(seq, np.ndarray):
        raise InputError(f"{src}: holds several arrays (.npz); give one (T, H, W) .npy array")
    encoder = get_registry(warn=not as_json).build("encoder", spec)
    t0 = time.perf_counter()
    try:
        out = encoder.encode(seq)
    except InputError as exc:  # the file's content is refused; any other error is a bug
        raise InputError(f"{src}: {exc}") from exc
    seconds = time.perf_counter() - t0
    dst = Path(out_path)
    dst.parent.mkdir(parents=True, exist_ok=True)
    np.save(dst, out)
    metadata = ENCODER.get(encoder, "metadata")
    meta = metadata() if metadata is not None else {
        "encoder": spec, "channels": list(encoder.channels)}
    meta = {**meta, "spec": spec, "input": str(src), "input_shape": list(seq.shape),
            "input_dtype": str(seq.dtype), "output": str(dst), "output_shape": list(out.shape),
            "seconds": round(seconds, 4),
            "ms_per_frame": round(1000 * seconds / max(1, out.shape[0]), 4)}
    meta_path = dst.with_suffix(".json")
    atomic_write_text(meta_path, json.dumps(meta, indent=2) + "\n")
    if as_json:
        click.echo(json.dumps({**meta, "metadata": str(meta_path)}, indent=2))
        return
    click.echo(f"{src} {tuple(seq.shape)} {seq.dtype} → {dst} {tuple(out.shape)} float32 "
               f"[{', '.join(meta.get('channels', []))}] in {seconds:.3f} s; "
               f"metadata: {meta_path}")
