"""The cost-against-accuracy plot draws cells whose seeds all scored the same."""

from __future__ import annotations


def test_a_band_a_rounding_error_inside_the_mean_is_drawn_without_error_bars():
    """Three seeds of one accuracy: the 95 % interval's ends came out a rounding error
    above the mean, and matplotlib refused the negative error bar (the plot failed the run
    and the report)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tactbench.runner.presentation.plots import plot_cost_vs_accuracy

    mean = 0.7
    summary = {"dataset": "d", "split": "paper", "encoder": "raw", "classifier": "logreg", "L": 3, "seeds": [0, 1, 2],
               "accuracy_mean": mean, "accuracy_std": 0.0,
               "accuracy_ci95": [mean + 1e-16, mean + 2e-16],
               "encode_ms_per_frame_mean": 0.5}
    assert 100 * summary["accuracy_ci95"][0] > 100 * mean - 1e-12
    fig = plot_cost_vs_accuracy([summary], {("d", "paper", "raw", "logreg"): "C0"}, labels={})
    try:
        (bars,) = fig.axes[0].containers  # the point and its (zero-length) error bar
        assert bars.has_yerr
    finally:
        plt.close(fig)
