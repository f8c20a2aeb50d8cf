"""Learning-curve plots: step and sample counts on the x axis read 200k, 1.2M."""
import json

import numpy as np
import pytest

from fr5_rl.training.evaluation import format_count, plot_learning_curve


@pytest.mark.parametrize("value, label", [
    (0, "0"), (500, "500"), (999, "999"), (1000, "1k"), (1500, "1.5k"), (200_000, "200k"), (250_000, "250k"),
    (1_000_000, "1M"), (1_200_000, "1.2M"), (1_250_000, "1.25M"), (12_000_000, "12M"), (999_999.9, "1M"),
    (0.5, "0.5"), (-200_000, "-200k"),
])
def test_format_count(value, label):
    assert format_count(value) == label
    assert format_count(value, 3) == label  # the (value, position) call of a FuncFormatter


@pytest.fixture
def saved_tick_labels(monkeypatch):
    """The x tick labels of every axes of each figure saved, read back after drawing."""
    from matplotlib.figure import Figure

    saved = []
    original = Figure.savefig

    def savefig(self, *args, **kwargs):
        result = original(self, *args, **kwargs)  # draws, so the tick labels are set
        saved.append([[tick.get_text() for tick in axes.get_xticklabels() if tick.get_text()]
                      for axes in self.axes])
        return result

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def _assert_count_labels(labels, largest_suffix):
    assert 3 <= len(labels) <= 8, labels
    for label in labels:
        assert label == "0" or label[-1] in "kM", f"tick label {label!r} is not a k/M count ({labels})"
    assert any(label.endswith(largest_suffix) for label in labels), labels


def test_rl_learning_curve_labels_steps_in_k_and_m(tmp_path, saved_tick_labels):
    run = tmp_path / "run"
    (run / "eval").mkdir(parents=True)
    steps = np.arange(1, 13) * 100_000  # 100k .. 1.2M
    rng = np.random.default_rng(0)
    np.savez(run / "eval" / "evaluations.npz", timesteps=steps, results=rng.normal(size=(12, 5)),
             successes=rng.random((12, 5)) > 0.5)
    (run / "summary.json").write_text(json.dumps({
        "task": "reach", "algo": "ppo", "time_to_solve_s": 211.5, "timesteps_to_solve": 280_000,
        "target_success": 0.95, "machine": {"cores": 2}}))
    out = plot_learning_curve(run, tmp_path / "curve.png")
    assert out.is_file() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (success_axis, return_axis), = saved_tick_labels
    for labels in (success_axis, return_axis):
        _assert_count_labels(labels, "M")
    assert "1M" in success_axis


def test_dagger_learning_curve_labels_samples_in_k(tmp_path, saved_tick_labels):
    run = tmp_path / "dagger"
    run.mkdir()
    history = [{"round": i, "samples": 20_000 * i, "wall_s": 30.0 * i, "eval_success": min(1.0, 0.3 * i)}
               for i in range(1, 5)]
    (run / "summary.json").write_text(json.dumps({"method": "dagger", "task": "grasp", "history": history,
                                                  "machine": {"cores": 2}}))
    out = plot_learning_curve(run, tmp_path / "dagger.png")
    assert out.is_file()
    (labels,), = saved_tick_labels
    _assert_count_labels(labels, "k")
