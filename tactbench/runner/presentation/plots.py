"""The figures of a run (matplotlib, Agg): one function per figure.

:func:`write_plots` draws every figure that applies; each ``plot_*`` function draws one
and :func:`caption` says what a figure shows, for report.md.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from tactbench.pareto import pareto_front
from tactbench.errors import InputError
from tactbench.runner.execution.questions import spec_label
from tactbench.runner.presentation.tables import labels_for

#: The top-level figures :func:`write_plots` may write besides ``confusion_*.png``.
#: The lowest encode cost drawn on the log axis (a cost of 0 ms is drawn there).
MIN_PLOTTED_COST_MS = 1e-4


_BAND_CI = "95 % CI of the mean over seeds"


_BAND_STD = "± std over seeds"


def accuracy_band(summary: dict[str, Any]) -> tuple[float, float, str] | None:
    """``(low, high, kind)`` of the band drawn around a summary's mean accuracy.

    The 95 % t-interval of the mean over seeds (``accuracy_ci95``) where there is one;
    else mean ± std where the std is a positive number over ≥ 2 seeds; else None (one
    seed: no band).
    """
    ci = summary.get("accuracy_ci95")
    if ci and all(isinstance(v, (int, float)) and math.isfinite(v) for v in ci):
        return float(ci[0]), float(ci[1]), _BAND_CI
    mean, std = summary.get("accuracy_mean"), summary.get("accuracy_std")
    if (len(summary.get("seeds", ())) > 1 and isinstance(std, (int, float))
            and math.isfinite(std) and std > 0 and math.isfinite(mean)):
        return mean - std, mean + std, _BAND_STD
    return None


def check_reference(reference: Iterable[dict[str, Any]] | None) -> list[dict[str, Any]]:
    """Validated published points to draw beside ours: each ``{"label": str, "L": int ≥ 1,
    "accuracy": fraction in [0, 1], "err": fraction ≥ 0 or None}`` (accuracy and err as
    fractions, like every accuracy tactbench reports)."""
    out = []
    for i, point in enumerate(reference or ()):
        where = f"reference point {i + 1}"
        if not isinstance(point, dict):
            raise InputError(f"{where} must be a mapping with label, L and accuracy, "
                             f"got {type(point).__name__}")
        missing = [k for k in ("label", "L", "accuracy") if k not in point]
        if missing:
            raise InputError(f"{where} lacks {', '.join(missing)} "
                             "(each needs label, L, accuracy and optionally err)")
        unknown = sorted(set(point) - {"label", "L", "accuracy", "err"})
        if unknown:
            raise InputError(f"{where} has unknown field(s) {', '.join(map(str, unknown))} "
                             "(known: label, L, accuracy, err)")
        label, length, acc, err = (point["label"], point["L"], point["accuracy"],
                                   point.get("err"))
        if not isinstance(label, str) or not label.strip():
            raise InputError(f"{where}: label must be a non-empty text, got {label!r}")
        if isinstance(length, bool) or not isinstance(length, int) or length < 1:
            raise InputError(f"{where} ({label}): L must be a whole number ≥ 1, "
                             f"got {length!r}")
        if (isinstance(acc, bool) or not isinstance(acc, (int, float))
                or not 0 <= acc <= 1):
            hint = f" (write {acc / 100:g} for {acc:g} %)" if (
                isinstance(acc, (int, float)) and not isinstance(acc, bool)
                and 1 < acc <= 100) else ""
            raise InputError(f"{where} ({label}): accuracy must be a fraction in [0, 1], "
                             f"got {acc!r}{hint}")
        if err is not None and (isinstance(err, bool) or not isinstance(err, (int, float))
                                or not 0 <= err <= 1):
            raise InputError(f"{where} ({label}): err must be a fraction in [0, 1], "
                             f"got {err!r}")
        out.append({"label": label, "L": length, "accuracy": float(acc),
                    "err": None if err is None else float(err)})
    return out


def _curve_key(s: dict[str, Any], labels: Mapping[str, str]) -> tuple:
    return s["dataset"], s["split"], s["encoder"], spec_label(s["classifier"], labels)


def _curve_keys(summaries: Sequence[dict[str, Any]], labels: Mapping[str, str] | None = None
                ) -> dict[tuple, list[dict[str, Any]]]:
    """(dataset, split, encoder, classifier label) → that curve's summaries, by L."""
    labels = labels_for(summaries=summaries) if labels is None else labels
    curves: dict[tuple, list[dict[str, Any]]] = {}
    for s in summaries:
        key = _curve_key(s, labels)
        curves.setdefault(key, []).append(s)
    for pts in curves.values():
        pts.sort(key=lambda s: s["L"])
    return dict(sorted(curves.items()))


def _curve_label(key: tuple, several_blocks: bool) -> str:
    dataset, split, enc, clf = key
    return f"{enc} / {clf}" + (f" [{dataset}, {split}]" if several_blocks else "")


def _seeds_text(points: Sequence[dict[str, Any]]) -> str:
    counts = sorted({len(s["seeds"]) for s in points})
    n = str(counts[0]) if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    return f"{n} seed" + ("" if counts == [1] else "s")


def band_note(points: Sequence[dict[str, Any]]) -> str:
    """What the band around a curve (or point) is: ``3 seeds, band: 95 % CI of the mean
    over seeds``, ``1 seed, no band``, ..."""
    kinds = []
    for s in points:
        band = accuracy_band(s)
        kind = band[2] if band else "no band"
        if kind not in kinds:
            kinds.append(kind)
    if kinds == ["no band"]:
        return f"{_seeds_text(points)}, no band"
    bands = [k for k in kinds if k != "no band"]
    text = f"{_seeds_text(points)}, band: " + " / ".join(bands)
    return text + (", none where one seed" if "no band" in kinds else "")


def _band_only(points: Sequence[dict[str, Any]]) -> str:
    """:func:`band_note` without the number of seeds: ``95 % CI of the mean over seeds``,
    ``no band``, ..."""
    return band_note(points).split(", ", 1)[1].removeprefix("band: ")


def l_curves_apply(summaries: Sequence[dict[str, Any]],
                   labels: Mapping[str, str] | None = None) -> bool:
    """Whether the L figures apply: some encoder × classifier has ≥ 2 values of L."""
    return any(len({s["L"] for s in pts}) >= 2
               for pts in _curve_keys(summaries, labels).values())


def write_plots(out: Path, summaries: Sequence[dict[str, Any]], *,
                reference: Iterable[dict[str, Any]] | None = None,
                labels: Mapping[str, str] | None = None) -> dict[str, Path]:
    """The figures of a run, as PNG in ``out``; returns name → path.

    - ``accuracy_vs_L`` (:func:`plot_accuracy_vs_l`) and ``per_class_vs_L``
      (:func:`plot_per_class_vs_l`): only when some line has ≥ 2 values of L;
    - ``cost_vs_accuracy`` (:func:`plot_cost_vs_accuracy`);
    - ``per_user_accuracy`` (:func:`plot_per_user_accuracy`): on users splits;
    - ``confusion_<encoder>_<classifier>_L<L>`` (:func:`plot_confusion`) for each summary
      (:func:`confusion_names`).

    A classifier is named by its label in ``labels`` (by default among the classifiers of
    ``summaries``; :func:`tactbench.runner.execution.questions.spec_labels`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    reference = check_reference(reference)
    labels = labels_for(summaries=summaries) if labels is None else labels
    names = confusion_names(summaries, labels)  # as caption() names them
    named = [(s, n) for s, n in zip(summaries, names) if not math.isnan(s["accuracy_mean"])]
    summaries = [s for s, _ in named]
    if not summaries:
        return {}
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {key: colours[i % len(colours)]
              for i, key in enumerate(_curve_keys(summaries, labels))}
    # (name, draw, dpi): each figure is drawn, saved and closed before the next
    todo: list[tuple[str, Any, int]] = []
    if l_curves_apply(summaries, labels):
        todo.append(("accuracy_vs_L",
                     lambda: plot_accuracy_vs_l(summaries, colour, reference, labels), 120))
    if any(not math.isnan(s["encode_ms_per_frame_mean"]) for s in summaries):
        todo.append(("cost_vs_accuracy",
                     lambda: plot_cost_vs_accuracy(summaries, colour, labels), 120))
    if l_curves_apply(summaries, labels):
        todo.append(("per_class_vs_L",
                     lambda: plot_per_class_vs_l(summaries, colour, labels), 110))
    if any(s.get("per_user_accuracy") for s in summaries):
        todo.append(("per_user_accuracy", lambda: plot_per_user_accuracy(summaries, labels),
                     110))
    for s, name in named:
        todo.append((name, lambda s=s: plot_confusion(s, labels), 110))
    figures: dict[str, Path] = {}
    for name, draw, dpi in todo:
        fig = draw()
        fig.set_label(name)
        figures[name] = out / f"{name}.png"
        fig.savefig(figures[name], dpi=dpi)
        plt.close(fig)
    return figures


def plot_accuracy_vs_l(summaries: Sequence[dict[str, Any]], colour: dict[tuple, str],
                       reference: Sequence[dict[str, Any]] = (),
                       labels: Mapping[str, str] | None = None):
    """Accuracy against L, a line per encoder × classifier with a shaded band
    (:func:`accuracy_band`), and ``reference`` (:func:`check_reference`), the published
    points, as open markers "study (published)"."""
    import matplotlib.pyplot as plt

    curves = _curve_keys(summaries, labels)
    several = len({k[:2] for k in curves}) > 1
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for key, pts in curves.items():
        xs = [s["L"] for s in pts]
        ys = [100 * s["accuracy_mean"] for s in pts]
        ax.plot(xs, ys, marker="o", color=colour[key],
                label=f"{_curve_label(key, several)} ({band_note(pts)})")
        bands = [accuracy_band(s) for s in pts]
        if any(bands):  # NaN where a point has no band: the shading stops there
            ax.fill_between(xs, [100 * b[0] if b else math.nan for b in bands],
                            [100 * b[1] if b else math.nan for b in bands],
                            color=colour[key], alpha=0.2, linewidth=0)
    markers = "DsPX^v*"
    encoders: dict[str, list[tuple]] = {}
    for key in curves:
        encoders.setdefault(key[2], []).append(key)
    for i, label in enumerate(dict.fromkeys(p["label"] for p in reference)):
        pts = sorted((p for p in reference if p["label"] == label), key=lambda p: p["L"])
        same = encoders.get(label, [])
        ax.errorbar([p["L"] for p in pts], [100 * p["accuracy"] for p in pts],
                    yerr=[100 * (p["err"] or 0) for p in pts]
                    if any(p["err"] for p in pts) else None,
                    marker=markers[i % len(markers)], markersize=8, linestyle=":",
                    markerfacecolor="white", capsize=3,
                    color=colour[same[0]] if len(same) == 1 else "black",
                    label=f"study (published): {label}")
    ax.set_xlabel("window length L (frames)")
    ax.set_ylabel("test accuracy (%)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_cost_vs_accuracy(summaries: Sequence[dict[str, Any]], colour: dict[tuple, str],
                          labels: Mapping[str, str] | None = None):
    """Accuracy against encode cost (log x), error bars from the band, the
    :func:`tactbench.pareto.pareto_front` as a step line with its members ringed."""
    import matplotlib.pyplot as plt

    labels = labels_for(summaries=summaries) if labels is None else labels
    drawn = [s for s in summaries if not math.isnan(s["encode_ms_per_frame_mean"])]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    costs = [max(s["encode_ms_per_frame_mean"], MIN_PLOTTED_COST_MS) for s in drawn]
    accs = [100 * s["accuracy_mean"] for s in drawn]
    for s, x, y in zip(drawn, costs, accs):
        band = accuracy_band(s)
        # seeds of one accuracy: the interval's ends can stand a rounding error inside it
        yerr = [[max(0.0, y - 100 * band[0])], [max(0.0, 100 * band[1] - y)]] if band else None
        ax.errorbar([x], [y], yerr=yerr, marker="o", capsize=3,
                    color=colour[_curve_key(s, labels)])
        ax.annotate(f"{s['encoder']} / {spec_label(s['classifier'], labels)} L={s['L']}",
                    (x, y), fontsize=7, xytext=(4, 4), textcoords="offset points")
    front = pareto_front([(s["encode_ms_per_frame_mean"], s["accuracy_mean"])
                          for s in drawn])
    ax.step([costs[i] for i in front], [accs[i] for i in front], where="post",
            color="crimson", linestyle="--", linewidth=1,
            label="Pareto front (not beaten on both accuracy and cost)")
    ax.scatter([costs[i] for i in front], [accs[i] for i in front], s=160,
               facecolors="none", edgecolors="crimson", linewidths=1.5, zorder=3)
    ax.set_xscale("log")
    ax.margins(x=0.35)  # room for the labels right of the points
    ax.set_xlabel("encode cost (ms per frame, one core, log scale)")
    ax.set_ylabel("test accuracy (%)")
    ax.set_title(f"error bars: {_band_only(drawn)}", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


def plot_per_class_vs_l(summaries: Sequence[dict[str, Any]], colour: dict[tuple, str],
                        labels: Mapping[str, str] | None = None):
    """One panel per class, a line per encoder × classifier (means over seeds)."""
    import matplotlib.pyplot as plt

    curves = _curve_keys(summaries, labels)
    several = len({k[:2] for k in curves}) > 1
    classes = list(dict.fromkeys(c for s in summaries for c in s["classes"]))
    ncols = min(3, len(classes))
    nrows = math.ceil(len(classes) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 2.6 * nrows + 0.6),
                             sharex=True, sharey=True, squeeze=False)
    for ax, cls in zip(axes.flat, classes):
        for key, pts in curves.items():
            pts = [s for s in pts if _finite(s["per_class_accuracy"].get(cls))]
            if pts:
                ax.plot([s["L"] for s in pts],
                        [100 * s["per_class_accuracy"][cls] for s in pts], marker="o",
                        markersize=4, color=colour[key], label=_curve_label(key, several))
        ax.set_title(cls, fontsize=9)
        ax.grid(alpha=0.3)
        ax.xaxis.get_major_locator().set_params(integer=True)
    for ax in list(axes.flat)[len(classes):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("L (frames)", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("class accuracy (%)", fontsize=8)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="lower center",
               ncol=min(4, max(1, len(labels))))
    fig.suptitle("per-class accuracy against L (mean over seeds)", fontsize=9)
    fig.tight_layout(rect=(0, 0.08 + 0.02 * math.ceil(len(labels) / 4), 1, 1))
    return fig


def plot_per_user_accuracy(summaries: Sequence[dict[str, Any]],
                           labels: Mapping[str, str] | None = None):
    """Each cell's accuracy per test user (a dot per user, mean over the runs testing
    them) with the median as a bar: how much people differ, at a glance."""
    import matplotlib.pyplot as plt
    import numpy as np

    cells = [s for s in summaries if s.get("per_user_accuracy")]
    fig, ax = plt.subplots(figsize=(max(4.0, 0.9 * len(cells) + 2), 4))
    rng = np.random.default_rng(0)  # the jitter, the same on every render
    for i, s in enumerate(cells):
        acc = 100 * np.array(sorted(s["per_user_accuracy"].values()), dtype=float)
        ax.scatter(i + rng.uniform(-0.15, 0.15, len(acc)), acc, s=12, alpha=0.7)
        ax.hlines(np.median(acc), i - 0.3, i + 0.3, colors="black")
    ax.set_xticks(range(len(cells)))
    ax.set_xticklabels([f"{s['encoder']}\n{spec_label(s['classifier'], labels)}\nL={s['L']}"
                        for s in cells], fontsize=8)
    ax.set_ylabel("accuracy on the user's recordings (%)")
    ax.set_ylim(-2, 102)
    ax.set_title("per-user accuracy (a dot per test user; bar: median)")
    fig.tight_layout()
    return fig


def confusion_names(summaries: Sequence[dict[str, Any]],
                    labels: Mapping[str, str] | None = None) -> list[str]:
    """The name of each summary's confusion figure, ``confusion_<encoder>_<classifier>_L<L>``
    (the classifier by its label, :func:`tactbench.runner.execution.questions.spec_labels`, slugged:
    ``confusion_raw_small-cnn-lstm-width-8_L5``). Names that slugging still makes alike
    get the first 8 hex digits of SHA-256 of the cell's encoder and classifier specs, so
    no figure overwrites another."""
    labels = labels_for(summaries=summaries) if labels is None else labels
    names = [f"confusion_{_slug(s['encoder'])}_{_slug(_file_label(s['classifier'], labels))}"
             f"_L{s['L']}" for s in summaries]
    cells = {}  # name → the distinct cells given it
    for name, s in zip(names, summaries):
        cells.setdefault(name, set()).add((str(s["encoder"]), str(s["classifier"]), s["L"]))
    return [name if len(cells[name]) == 1 else f"{name}_{_digest(s)}"
            for name, s in zip(names, summaries)]


def _digest(summary: dict[str, Any]) -> str:
    text = f"{summary['encoder']}|{summary['classifier']}"
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def _file_label(spec: str, labels: Mapping[str, str]) -> str:
    """A classifier's label for a file name, before :func:`_slug`:
    ``small-cnn-lstm (lr=0.1; width=8)`` → ``small-cnn-lstm lr=0.1 width=8`` (slugged:
    ``small-cnn-lstm-lr-0-1-width-8``)."""
    return spec_label(spec, labels).replace(" (", " ").replace("; ", " ").rstrip(")")


def plot_confusion(summary: dict[str, Any], labels: Mapping[str, str] | None = None):
    """A summary's confusion matrix, rows normalised per seed and averaged."""
    import matplotlib.pyplot as plt

    classes = summary["classes"]
    matrix = summary["confusion_normalised"]
    fig, ax = plt.subplots(figsize=(1.0 + 0.8 * len(classes), 0.8 + 0.8 * len(classes)))
    ax.imshow(matrix, vmin=0, vmax=1, cmap="Blues")
    for i, line in enumerate(matrix):
        for j, v in enumerate(line):
            ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=8,
                    color="white" if v > 0.5 else "black")
    ax.set_xticks(range(len(classes)), classes, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(classes)), classes, fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(f"{summary['encoder']} / {spec_label(summary['classifier'], labels)}, "
                 f"L={summary['L']}", fontsize=9)
    fig.tight_layout()
    return fig


def caption(name: str, summaries: Sequence[dict[str, Any]],
            reference: Sequence[dict[str, Any]], labels: Mapping[str, str] | None = None
            ) -> str:
    """What figure ``name`` shows, for report.md (``labels`` as :func:`write_plots`'s)."""
    labels = labels_for(summaries=summaries) if labels is None else labels
    curves = _curve_keys(summaries, labels)
    several = len({k[:2] for k in curves}) > 1
    if name == "accuracy_vs_L":
        notes = {_curve_label(k, several): band_note(pts) for k, pts in curves.items()}
        bands = ("every line: " + next(iter(notes.values())) if len(set(notes.values())) == 1
                 else "; ".join(f"{label}: {note}" for label, note in notes.items()))
        text = ("Accuracy against window length L, mean over seeds; the shaded band is the "
                "95 % t-interval of the mean over seeds (± std where no interval could be "
                f"computed, none with one seed). Bands: {bands}.")
        if reference:
            text += (" Open markers on dotted lines: the study's published points "
                     "(\"study (published)\"), with their error bars where given.")
        return text
    if name == "cost_vs_accuracy":
        drawn = [s for s in summaries if not math.isnan(s["encode_ms_per_frame_mean"])]
        costs = [s["encode_ms_per_frame_mean"] for s in drawn]
        front = pareto_front(list(zip(costs, [s["accuracy_mean"] for s in drawn])))
        members = ", ".join(
            f"{drawn[i]['encoder']} / {spec_label(drawn[i]['classifier'], labels)} "
            f"L={drawn[i]['L']} "
            f"({costs[i]:.3g} ms, {100 * drawn[i]['accuracy_mean']:.1f} %)" for i in front)
        return ("Accuracy against encode cost (ms per frame on one core, log scale; a cost "
                f"below {MIN_PLOTTED_COST_MS:g} ms is drawn at {MIN_PLOTTED_COST_MS:g}), "
                f"error bars: {_band_only(drawn)}. Dashed step line and "
                "rings: the Pareto front, the cells no other cell beats on both accuracy and "
                f"cost: {members}.")
    if name == "per_user_accuracy":
        return ("Accuracy of each cell on each test user's recordings (a dot per user, the "
                "mean over the runs that test them; the bar is the median over users). "
                "The values are in results.json, `summary[].per_user_accuracy`.")
    if name == "per_class_vs_L":
        return ("Per-class accuracy against window length L, one panel per class, a line "
                "per encoder × classifier; means over seeds, no bands.")
    cell = next((f"{s['encoder']} / {spec_label(s['classifier'], labels)}, L={s['L']}"
                 for s, own in zip(summaries, confusion_names(summaries, labels))
                 if name == own), name)
    return (f"Confusion matrix of {cell}: each true class's row normalised per seed, then "
            "averaged over seeds.")


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in text).strip("-")

