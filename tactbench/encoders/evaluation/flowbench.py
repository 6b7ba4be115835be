"""Flow error against run time, on scenes with a known motion field.

Tactile scenes are made of contacts (anisotropic Gaussian pressure blobs, joined
with a soft union ``1 - Π(1 - a_i g_i)`` so values stay in [0, 1]) that move
with an analytic motion field; each frame is rendered from the continuous
pattern, so the ground truth is exact:

``translate``
    every contact moves by ``speed`` px/frame in one direction.
``twist``
    rotation about the image centre; contacts sit on a ring of radius ``r`` and
    move ``speed`` px/frame along it (angular step ``speed / r``).
``push``
    expansion about the contact's centre: ``x ↦ c + s (x - c)`` with ``s`` chosen
    so a point at 2σ moves ``speed`` px/frame.
``pull``
    elongated contacts slip by ``speed`` px/frame along −x, away from a palm
    contact that stays still (a motion boundary).
``pressure``
    pressure grows by 25 % per frame at fixed position: the true flow is zero,
    so anything a method reports is error from brightness change.

Contact sizes are fractions of the image's shorter side (``small`` σ = 3 %,
``large`` σ = 8 %: 2.0 and 5.4 px at the default 72 × 67, 10 and 27 px at
357 × 334), speeds are in
pixels per frame of the image (0.25 – 8). The natural-image sanity check warps
scikit-image's ``camera`` by a smooth sinusoidal field (up to 2 px/frame).

Errors are measured where there is something to see: pixels where
``max(I_{k-1}, I_k) ≥ 0.1`` (tactile) or everywhere but a 4 px border (natural).
Endpoint error (EPE) is ``|u - u_gt|`` in px; angular error is Barron's angle
between ``(u, 1)`` and ``(u_gt, 1)`` in degrees. Time is the median over
repeated runs (same process, same input) of one ``encode`` call on a 16-frame
tactile sequence, divided by its 16 frame pairs: what a user pays per frame.
"""

from __future__ import annotations

import csv
import io
import json
import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from tactbench.pareto import pareto_front
from tactbench.encoders.flow import is_flow_encoder
from tactbench.errors import InputError
from tactbench.paths import atomic_write_bytes, atomic_write_text

MOTIONS = ("translate", "twist", "push", "pull", "pressure")
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
SIZES = {"small": 0.03, "large": 0.08}
#: The encoders compared when none are named.
DEFAULT_ENCODERS = ("farneback", "lucas-kanade", "kornia-flow", "dis", "tvl1")
#: The runner's quick profile: the 357 × 334 mm forearm at 5 mm pixels.
DEFAULT_SHAPE = (72, 67)
FULL_SHAPE = (357, 334)
MASK_THRESHOLD = 0.1


@dataclass
class FlowScene:
    """Frame pairs with their true forward flow (not the runner's run configuration,
    :class:`tactbench.runner.Scene`).

    ``prev``, ``curr``: float32 ``(P, H, W)`` in [0, 1]; ``flow``: float32
    ``(P, H, W, 2)`` px/frame with ``curr(x + flow) = prev(x)``; ``mask``:
    bool ``(P, H, W)``, where the error is measured.
    """

    name: str
    motion: str
    speed: float
    size: str
    prev: np.ndarray
    curr: np.ndarray
    flow: np.ndarray
    mask: np.ndarray
    tactile: bool = True

    @property
    def shape(self) -> tuple[int, int]:
        return self.prev.shape[1], self.prev.shape[2]


# ----------------------------------------------------------------------------- scenes


@dataclass
class _Contact:
    cx: float
    cy: float
    sx: float
    sy: float
    angle: float
    amp: float
    moving: bool = True


def _render(contacts: Sequence[_Contact], grid: tuple[np.ndarray, np.ndarray],
            inverse: Callable[[np.ndarray, np.ndarray, _Contact], tuple[np.ndarray, np.ndarray]],
            gain: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Render contacts after mapping pixel positions back to the reference frame.

    Returns the image (H, W) float64 in [0, 1] and the index of the strongest
    contact at each pixel (to assign piecewise ground truth).
    """
    ys, xs = grid
    rest = np.ones_like(xs)
    strongest = np.zeros(xs.shape, dtype=np.int64)
    best = np.zeros_like(xs)
    for i, c in enumerate(contacts):
        rx, ry = inverse(xs, ys, c)
        dx, dy = rx - c.cx, ry - c.cy
        ca, sa = math.cos(c.angle), math.sin(c.angle)
        u = (ca * dx + sa * dy) / c.sx
        v = (-sa * dx + ca * dy) / c.sy
        g = min(1.0, c.amp * gain) * np.exp(-0.5 * (u * u + v * v))
        rest *= 1.0 - g
        stronger = g > best
        strongest[stronger] = i
        best[stronger] = g[stronger]
    return 1.0 - rest, strongest


def _true_flow(motion: str, grid: tuple[np.ndarray, np.ndarray],
               centre: tuple[float, float], contacts: list[_Contact], owner: np.ndarray, *,
               speed: float, theta: float, omega: float, scale: float) -> np.ndarray:
    """The true flow ``(H, W, 2)`` (u, v in px) of one frame pair of a tactile scene:
    ``grid`` the pixel rows and columns, ``owner`` the contact each pixel belongs to."""
    ys, xs = grid
    cy0, cx0 = centre
    if motion == "translate":
        u = np.full_like(xs, speed * math.cos(theta))
        v = np.full_like(xs, speed * math.sin(theta))
    elif motion == "twist":
        dx, dy = xs - cx0, ys - cy0
        u = cx0 + math.cos(omega) * dx - math.sin(omega) * dy - xs
        v = cy0 + math.sin(omega) * dx + math.cos(omega) * dy - ys
    elif motion == "push":
        c = contacts[0]
        u, v = (scale - 1.0) * (xs - c.cx), (scale - 1.0) * (ys - c.cy)
    elif motion == "pull":
        moving = np.array([c.moving for c in contacts])[owner]
        u, v = np.where(moving, -speed, 0.0), np.zeros_like(xs)
    else:
        u, v = np.zeros_like(xs), np.zeros_like(xs)
    return np.stack([u, v], axis=-1)


def tactile_scene(motion: str, speed: float, size: str, shape: tuple[int, int], *,
                  pairs: int = 2, seed: int = 0) -> FlowScene:
    """One tactile scene: ``pairs`` consecutive frame pairs under ``motion``."""
    if motion not in MOTIONS:
        raise InputError(f"unknown motion '{motion}'; motions: {', '.join(MOTIONS)}")
    if size not in SIZES:
        raise InputError(f"unknown contact size '{size}'; sizes: {', '.join(SIZES)}")
    h, w = shape
    rng = np.random.default_rng([seed, MOTIONS.index(motion), int(speed * 1000),
                                 list(SIZES).index(size), h, w])
    side = min(h, w)
    sigma = SIZES[size] * side
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    cy0, cx0 = (h - 1) / 2.0, (w - 1) / 2.0
    theta = rng.uniform(0, 2 * math.pi)  # translation direction
    omega = scale = 0.0  # twist's angle and push's scale per frame, set below
    contacts: list[_Contact] = []

    def fingertips(n: int, radius: float, elong: float = 1.3) -> None:
        for j in range(n):
            a = 2 * math.pi * j / n + rng.uniform(-0.3, 0.3)
            contacts.append(_Contact(cx0 + radius * math.cos(a), cy0 + radius * math.sin(a),
                                     sigma * elong, sigma, rng.uniform(0, math.pi),
                                     rng.uniform(0.6, 0.9)))

    if motion in ("translate", "pressure"):
        fingertips(3, 0.22 * side)
    elif motion == "twist":
        radius = 0.28 * side
        fingertips(4, radius)
        omega = speed / radius
    elif motion == "push":
        contacts.append(_Contact(cx0, cy0, sigma * 1.6, sigma * 1.2, rng.uniform(0, math.pi),
                                 0.8))
        scale = 1.0 + speed / (2.0 * sigma * 1.6)
    else:  # pull: elongated fingers slip along -x, away from the palm, which stays
        for j in (-1, 1):
            contacts.append(_Contact(cx0 - 0.05 * side, cy0 + j * 0.18 * side, sigma * 2.0,
                                     sigma * 0.8, 0.0, rng.uniform(0.6, 0.9)))
        contacts.append(_Contact(cx0 + 0.25 * side, cy0, sigma, sigma * 1.5, 0.0, 0.7,
                                 moving=False))

    def make_inverse(k: int):
        """Map frame-k pixel positions to reference (frame 0) positions."""
        def inverse(x, y, c: _Contact):
            if motion == "translate":
                return x - k * speed * math.cos(theta), y - k * speed * math.sin(theta)
            if motion == "twist":
                a = -k * omega
                dx, dy = x - cx0, y - cy0
                return (cx0 + math.cos(a) * dx - math.sin(a) * dy,
                        cy0 + math.sin(a) * dx + math.cos(a) * dy)
            if motion == "push":
                s = scale ** -k
                return c.cx + s * (x - c.cx), c.cy + s * (y - c.cy)
            if motion == "pull" and c.moving:
                return x + k * speed, y
            return x, y
        return inverse

    frames, owners = [], []
    for k in range(pairs + 1):
        gain = 1.25 ** k / 1.25 ** pairs if motion == "pressure" else 1.0
        img, owner = _render(contacts, (ys, xs), make_inverse(k), gain)
        frames.append(img)
        owners.append(owner)

    flows = [_true_flow(motion, (ys, xs), (cy0, cx0), contacts, owners[k], speed=speed,
                        theta=theta, omega=omega, scale=scale) for k in range(pairs)]

    stack = np.asarray(frames, dtype=np.float32)
    prev, curr = stack[:-1], stack[1:]
    mask = np.maximum(prev, curr) >= MASK_THRESHOLD
    label = f"{motion}/{size}" + ("" if motion == "pressure" else f"/{speed:g}px")
    return FlowScene(label, motion, speed if motion != "pressure" else 0.0, size, prev,
                 np.ascontiguousarray(curr), np.asarray(flows, dtype=np.float32), mask)


def natural_scene(shape: tuple[int, int], *, amplitude: float = 2.0) -> FlowScene:
    """scikit-image's ``camera`` warped by a smooth sinusoidal flow (≤ ``amplitude`` px)."""
    import cv2
    from skimage import data

    h, w = shape
    img = cv2.resize(data.camera().astype(np.float32) / 255.0, (w, h),
                     interpolation=cv2.INTER_AREA)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    u = amplitude * np.sin(2 * math.pi * ys / h) * 0.8 + 0.6 * amplitude * np.cos(
        2 * math.pi * xs / w)
    v = amplitude * np.cos(2 * math.pi * xs / w) * 0.5 + 0.5 * amplitude
    u, v = np.clip(u, -amplitude, amplitude), np.clip(v, -amplitude, amplitude)
    # prev(x) = curr(x + u(x)): render prev by sampling curr along the flow.
    prev = cv2.remap(img, xs + u, ys + v, interpolation=cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REFLECT)
    prev = np.clip(prev, 0.0, 1.0)
    mask = np.zeros((h, w), dtype=bool)
    b = min(4, h // 4, w // 4)
    mask[b:h - b, b:w - b] = True
    return FlowScene("natural/camera", "natural", float(amplitude), "-", prev[None],
                 img[None], np.stack([u, v], axis=-1)[None].astype(np.float32), mask[None],
                 tactile=False)


def default_scenes(shape: tuple[int, int], *, full: bool = False,
                   seed: int = 0) -> list[FlowScene]:
    """The benchmark's scenes at ``shape``: every motion × speed × size, then the natural one.

    ``full=True`` (for large images) keeps fewer speeds and one pair per scene,
    so slow methods finish in reasonable time.
    """
    speeds = (0.5, 2.0, 8.0) if full else SPEEDS
    pairs = 1 if full else 2
    scenes = []
    for motion in MOTIONS:
        for size in SIZES:
            for speed in (speeds if motion != "pressure" else (0.0,)):
                scenes.append(tactile_scene(motion, speed, size, shape, pairs=pairs, seed=seed))
    scenes.append(natural_scene(shape))
    return scenes


def timing_sequence(shape: tuple[int, int], frames: int = 16) -> np.ndarray:
    """A ``frames``-long tactile sequence (contacts translating 1 px/frame) for timing."""
    scene = tactile_scene("translate", 1.0, "small", shape, pairs=frames - 1)
    return np.concatenate([scene.prev, scene.curr[-1:]])


def memory_estimate(shapes: Sequence[tuple[int, int]]) -> int:
    """Bytes :func:`run_flowbench` holds at ``shapes``, estimated before any scene is made:
    every shape's scenes (float32 frame pairs and their float64 true flow) and timing
    sequence are built up front; the largest shape's encoding of the timing sequence
    (4 float32 channels) and an encoder's working copies (pyramids, gradients: taken as 8
    images of the size) come on top."""
    total, largest = 0, 0
    for h, w in shapes:
        full = h * w > 128 * 128
        speeds = 3 if full else len(SPEEDS)
        pairs = 1 if full else 2
        moving = sum(m != "pressure" for m in MOTIONS)
        n_scenes = len(SIZES) * (moving * speeds + len(MOTIONS) - moving) + 1
        total += n_scenes * pairs * h * w * (2 * 4 + 2 * 8)  # prev, curr; u, v
        total += 16 * h * w * 4  # the timing sequence
        largest = max(largest, h * w)
    return int(total + largest * (16 * 4 * 4 + 8 * 8))


# ----------------------------------------------------------------------------- errors


def endpoint_error(flow: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``|flow - truth|`` per pixel, px: ``(..., 2)`` → ``(...)``."""
    d = flow.astype(np.float64) - truth
    return np.hypot(d[..., 0], d[..., 1])


def angular_error(flow: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Barron's angular error in degrees between ``(u, v, 1)`` and ``(u_gt, v_gt, 1)``."""
    f = flow.astype(np.float64)
    g = truth.astype(np.float64)
    num = f[..., 0] * g[..., 0] + f[..., 1] * g[..., 1] + 1.0
    den = np.sqrt((f ** 2).sum(-1) + 1.0) * np.sqrt((g ** 2).sum(-1) + 1.0)
    return np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0)))


# ----------------------------------------------------------------------------- running


@dataclass
class EncoderResult:
    """One encoder at one resolution: summary numbers and per-scene rows."""

    encoder: str
    resolution: str
    epe: float
    angular: float
    ms_per_pair: float
    natural_epe: float
    per_motion: dict[str, float] = field(default_factory=dict)
    scenes: list[dict[str, Any]] = field(default_factory=list)
    pareto: bool = False

    def summary(self) -> dict[str, Any]:
        return {"encoder": self.encoder, "resolution": self.resolution,
                "epe_px": self.epe, "angular_deg": self.angular,
                "ms_per_pair": self.ms_per_pair, "natural_epe_px": self.natural_epe,
                "epe_by_motion_px": self.per_motion, "pareto": self.pareto}


def time_encoder(encoder: Any, seq: np.ndarray, *, repeats: int = 5) -> float:
    """Median ms per frame pair of ``encoder.encode(seq)`` over ``repeats`` runs (+1 warm-up)."""
    encoder.encode(seq)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        encoder.encode(seq)
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times) / seq.shape[0]


def evaluate(encoder: Any, scenes: Iterable[FlowScene]) -> list[dict[str, Any]]:
    """EPE and angular error of ``encoder.flow`` on each scene (one row per scene)."""
    rows = []
    for scene in scenes:
        est = encoder.flow(scene.prev, scene.curr)
        epe = endpoint_error(est, scene.flow)[scene.mask]
        ae = angular_error(est, scene.flow)[scene.mask]
        rows.append({"scene": scene.name, "motion": scene.motion, "speed": scene.speed,
                     "size": scene.size, "tactile": scene.tactile,
                     "epe_px": float(epe.mean()), "angular_deg": float(ae.mean())})
    return rows


def resolution_label(shape: tuple[int, int]) -> str:
    return f"{shape[0]}x{shape[1]}"


def run_flowbench(encoders: Sequence[tuple[str, Any]],
                  shapes: Sequence[tuple[int, int]] = (DEFAULT_SHAPE, FULL_SHAPE), *,
                  repeats: int = 5,
                  progress: Callable[..., None] | None = None) -> list[EncoderResult]:
    """Measure every ``(spec, encoder)`` at every shape; Pareto front marked per shape.

    ``progress(done, total, item=...)`` is called before each encoder × shape (``item``
    names it) and once at the end. Every encoder must be a flow encoder
    (:func:`tactbench.encoders.flow.is_flow_encoder`), else :class:`InputError`.
    """
    plans = []
    for shape in shapes:
        full = shape[0] * shape[1] > 128 * 128
        plans.append((shape, default_scenes(shape, full=full), timing_sequence(shape)))
    total = len(plans) * len(encoders)
    done = 0
    results: list[EncoderResult] = []
    for shape, scenes, seq in plans:
        group = []
        for spec, enc in encoders:
            if progress:
                progress(done, total, item=f"{spec} @ {resolution_label(shape)}")
            if not is_flow_encoder(enc):
                raise InputError(f"encoder '{spec}' is not a flow encoder (it needs magnitude "
                                 f"and direction channels, flow(prev, curr), max_flow and "
                                 f"min_magnitude); flowbench compares flow encoders only")
            rows = evaluate(enc, scenes)
            tactile = [r for r in rows if r["tactile"]]
            natural = [r for r in rows if not r["tactile"]]
            per_motion = {m: float(np.mean([r["epe_px"] for r in tactile if r["motion"] == m]))
                          for m in MOTIONS if any(r["motion"] == m for r in tactile)}
            group.append(EncoderResult(
                encoder=spec, resolution=resolution_label(shape),
                epe=float(np.mean([r["epe_px"] for r in tactile])),
                angular=float(np.mean([r["angular_deg"] for r in tactile])),
                ms_per_pair=time_encoder(enc, seq, repeats=repeats),
                natural_epe=float(np.mean([r["epe_px"] for r in natural])) if natural
                else float("nan"),
                per_motion=per_motion, scenes=rows))
            done += 1
        front = set(pareto_front([(r.ms_per_pair, -r.epe) for r in group]))
        for res, flag in zip(group, (i in front for i in range(len(group)))):
            res.pareto = flag
        results.extend(group)
    if progress:
        progress(total, total, item="done")
    return results


# ----------------------------------------------------------------------------- outputs


def plot(results: Sequence[EncoderResult], path: Path) -> Path:
    """``flow_error_vs_time.png``: EPE against ms per pair, one panel per resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import ticker

    resolutions = list(dict.fromkeys(r.resolution for r in results))
    fig, axes = plt.subplots(1, len(resolutions), figsize=(5.5 * len(resolutions), 4.2),
                             squeeze=False)
    for ax, res in zip(axes[0], resolutions):
        group = [r for r in results if r.resolution == res]
        for r in group:
            ax.scatter(r.ms_per_pair, r.epe, s=60 if r.pareto else 30,
                       marker="o" if r.pareto else "x",
                       color="tab:red" if r.pareto else "tab:gray", zorder=3)
            ax.annotate(r.encoder, (r.ms_per_pair, r.epe), textcoords="offset points",
                        xytext=(5, 4), fontsize=8)
        front = sorted((r.ms_per_pair, r.epe) for r in group if r.pareto)
        if front:
            ax.step([p[0] for p in front], [p[1] for p in front], where="post",
                    color="tab:red", alpha=0.5, label="Pareto front")
            ax.legend(loc="upper right", fontsize=8)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _pos: f"{v:g}"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
        ax.set_xlabel("ms per frame pair (median, 1 process)")
        ax.set_ylabel("mean endpoint error on tactile scenes (px)")
        ax.set_title(f"{res} px")
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, png.getvalue())
    return path


def to_document(results: Sequence[EncoderResult], meta: dict[str, Any]) -> dict[str, Any]:
    """The JSON document ``tactbench flowbench --json`` prints and writes."""
    return {"meta": meta, "results": [r.summary() for r in results],
            "scenes": [{"encoder": r.encoder, "resolution": r.resolution, **row}
                       for r in results for row in r.scenes]}


def write_outputs(results: Sequence[EncoderResult], out: Path,
                  meta: dict[str, Any]) -> dict[str, Path]:
    """Write ``flowbench.json``, ``flowbench.csv`` (per scene) and the plot into ``out``,
    each atomically (a reader sees the old file or the new one, never half)."""
    doc = to_document(results, meta)
    paths = {"json": out / "flowbench.json", "csv": out / "flowbench.csv",
             "png": out / "flow_error_vs_time.png"}
    atomic_write_text(paths["json"], json.dumps(doc, indent=2) + "\n")
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=["encoder", "resolution", "scene", "motion",
                                               "speed", "size", "tactile", "epe_px",
                                               "angular_deg"])
    writer.writeheader()
    writer.writerows(doc["scenes"])
    atomic_write_text(paths["csv"], table.getvalue())
    plot(results, paths["png"])
    return paths
