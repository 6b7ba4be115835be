"""``tactbench encode``: encode one sequence file with any registered encoder."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import click

from tactbench.boundary import BoundaryError, encoder_output_problem
from tactbench.budget import check_budget
from tactbench.cli import get_registry, json_text
from tactbench.contracts import ENCODER
from tactbench.errors import InputError
from tactbench.integrity import check_regular_file, read_npy_header, read_regular_bytes
from tactbench.paths import atomic_write_text, check_output_file, temp_name


@click.command("encode")
@click.option("--encoder", "-e", "spec", required=True,
              help="Encoder name and options, e.g. 'farneback:winsize=9,levels=2'.")
@click.option("--input", "-i", "input_path", required=True, type=click.Path(dir_okay=False),
              help="A .npy file with a (T, H, W) sequence: float in [0, 1] or unsigned ints.")
@click.option("--out", "-o", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Where to write the float32 (T, C, H, W) .npy (.npy is added when OUT "
                   "lacks it); metadata goes beside it as .json. An existing file is "
                   "replaced only when an earlier 'tactbench encode' wrote it; never the "
                   "input.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def encode_cmd(spec: str, input_path: str, out_path: str, as_json: bool) -> None:
    """Encode a (T, H, W) sequence into (T, C, H, W) feature images.

    The metadata file (OUT with suffix .json) records the encoder, its version
    and options, the channel names and ranges, and for flow encoders the
    magnitude scale in pixels per frame.
    """
    import numpy as np


    src = Path(input_path)
    check_regular_file(src)  # a FIFO or a device: one line, never opened
    dst = output_paths(out_path)
    meta_path = dst.with_suffix(".json")
    for target in (dst, meta_path):
        check_output_file(target, option="--out", inputs=[src], ours=_ours)
    encoder = get_registry(warn=not as_json).build("encoder", spec)
    shape, dtype = _npy_header(src)
    if len(shape) == 3:  # the input, its float32 copy, and the (T, C, H, W) output
        t, h, w = shape
        c = len(tuple(ENCODER.get(encoder, "channels")))
        check_budget(dtype.itemsize * t * h * w + 4 * t * h * w * (1 + c),
                     f"encoding {src} ({t} frames of {h}×{w} px into {c} channels)")
    try:
        seq = np.load(src, allow_pickle=False)
    except Exception as exc:  # numpy raises several types for a bad file
        raise InputError(f"{src}: not a readable .npy array ({type(exc).__name__}: {exc})")
    t0 = time.perf_counter()
    try:
        out = encoder.encode(seq)
    except InputError as exc:  # the file's content is refused; any other error is a bug
        raise InputError(f"{src}: {exc}") from exc
    seconds = time.perf_counter() - t0
    channels = len(tuple(ENCODER.get(encoder, "channels")))
    problem = encoder_output_problem(out, (len(seq), channels, *np.shape(seq)[1:]),
                                     tuple(ENCODER.get(encoder, "ranges")))
    if problem is not None:  # a plugin's output: checked before it is written
        raise BoundaryError.of("encoder", spec, "", problem)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(temp_name(dst.name))  # written whole, then renamed over dst
    try:
        with open(tmp, "wb") as fh:
            np.save(fh, out)
        os.replace(tmp, dst)
    finally:
        tmp.unlink(missing_ok=True)
    metadata = ENCODER.get(encoder, "metadata")
    meta = metadata() if metadata is not None else {
        "encoder": spec, "channels": list(encoder.channels)}
    meta = {**meta, "spec": spec, "input": str(src), "input_shape": list(seq.shape),
            "input_dtype": str(seq.dtype), "output": str(dst), "output_shape": list(out.shape),
            "seconds": round(seconds, 4),
            "ms_per_frame": round(1000 * seconds / max(1, out.shape[0]), 4)}
    atomic_write_text(meta_path, json.dumps(meta, indent=2) + "\n")
    if as_json:
        click.echo(json_text({**meta, "metadata": str(meta_path)}, indent=2))
        return
    click.echo(f"{src} {tuple(seq.shape)} {seq.dtype} → {dst} {tuple(out.shape)} float32 "
               f"[{', '.join(meta.get('channels', []))}] in {seconds:.3f} s; "
               f"metadata: {meta_path}")


def output_paths(out_path: str) -> Path:
    """The .npy file ``-o`` names: OUT itself when it ends in ``.npy``, else OUT.npy
    (what numpy would write); this is the name printed and recorded."""
    dst = Path(out_path)
    return dst if dst.suffix.lower() == ".npy" else dst.with_name(dst.name + ".npy")


def _ours(path: Path) -> bool:
    """Whether ``path`` (an encoding or its metadata) is an earlier ``tactbench encode``
    output: the metadata beside it parses and records that encoding as its output."""
    meta_path = path.with_suffix(".json")
    try:
        meta = json.loads(read_regular_bytes(meta_path, limit=1 << 20))  # never a FIFO
        recorded = Path(meta["output"])
        return (isinstance(meta, dict) and "spec" in meta
                and recorded.name == path.with_suffix(".npy").name)
    except (OSError, ValueError, KeyError, TypeError):
        return False


def _npy_header(src: Path):
    """``(shape, dtype)`` from a .npy file's header, checked against the file's size, so
    that a header claiming more than the file holds is refused before anything is read."""

    try:
        with open(src, "rb") as fh:
            if fh.read(4) == b"PK\x03\x04":
                raise InputError(f"{src}: holds several arrays (.npz); give one (T, H, W) "
                                 f".npy array")
            fh.seek(0)
            shape, _, dtype = read_npy_header(fh)
            offset = fh.tell()
        size = src.stat().st_size
    except InputError:  # an InputError is a ValueError too: keep its message
        raise
    except ValueError as exc:
        raise InputError(f"{src}: not a readable .npy array ({exc})") from None
    except OSError as exc:
        raise InputError(f"{src}: cannot read it ({exc.strerror or exc})") from None
    if dtype.hasobject:
        raise InputError(f"{src}: holds Python objects, not numbers; give a numeric "
                         f"(T, H, W) array")
    if len(shape) != 3:
        raise InputError(f"{src}: expected a (T, H, W) sequence, got shape {shape}")
    need = math.prod(shape) * dtype.itemsize
    if need > size - offset:
        raise InputError(f"{src}: truncated: its header says shape {shape} {dtype} "
                         f"({need} bytes) and the file holds {size - offset}")
    return shape, dtype
