"""scripts/probe_oscillator_authors.py: the authors' Keras weights in our network, our training
from an export, and the summary at fixed update counts (no TensorFlow here: a synthetic export)."""

import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import probe_oscillator_authors as probe  # noqa: E402

sys.path.remove(str(ROOT / "scripts"))

SIZES = [4, 20, 20, 20, 96]


def keras_weights(rng) -> list[np.ndarray]:
    """Dense layers as Keras stores them: kernel (in, out), then bias (out,)."""
    out = []
    for n_in, n_out in zip(SIZES[:-1], SIZES[1:]):
        out += [rng.normal(size=(n_in, n_out)).astype(np.float32) / np.sqrt(n_in), rng.normal(size=n_out).astype(np.float32)]
    return out


def keras_forward(weights: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """x @ kernel + bias, ReLU on the hidden layers: Keras's Dense, written out."""
    for i, (kernel, bias) in enumerate(zip(weights[::2], weights[1::2])):
        x = x @ kernel + bias
        if i < len(weights) // 2 - 1:
            x = np.maximum(x, 0.0)
    return x


def test_keras_weights_give_our_network_the_keras_function():
    from higbench.problems.networks import mlp

    rng = np.random.default_rng(0)
    weights, x = keras_weights(rng), rng.random((5, 4)).astype(np.float32)
    model = mlp(SIZES, activation="relu")
    probe.load_keras_weights(model, weights)
    with torch.no_grad():
        ours = model(torch.as_tensor(x)).numpy()
    np.testing.assert_allclose(ours, keras_forward(weights, x), rtol=1e-5, atol=1e-5)


def write_export(path: Path, n: int = 256) -> Path:
    rng = np.random.default_rng(1)
    weights = keras_weights(rng)
    np.savez(path, x_train=rng.random((n, 4)).astype(np.float32), x_test=rng.random((n, 4)).astype(np.float32),
             **{f"weight_{i}": w for i, w in enumerate(weights)}, train_loss=np.array([1.0, 0.5]),
             test_loss=np.array([1.1, 0.6]), epoch_seconds=np.array([2.0]), updates_per_epoch=n // 128)  # fmt: skip
    return path


def test_variants_start_from_the_exports_data_and_weights_and_train(tmp_path):
    export = write_export(tmp_path / "export.npz")
    threads = torch.get_num_threads()
    try:
        runs = {v.name: probe.train(v, export, epochs=1) for v in probe.VARIANTS if v.name in ("mirror", "reshuffled", "ours")}
    finally:
        torch.set_num_threads(threads)
    mirror, reshuffled, ours = runs["mirror"], runs["reshuffled"], runs["ours"]
    assert mirror["updates"].tolist() == [0, 2]  # 256 exported samples, b = 128
    assert ours["updates"].tolist() == [0, 32]  # our 4,096 samples
    assert mirror["test_loss"].iloc[0] == reshuffled["test_loss"].iloc[0] != ours["test_loss"].iloc[0]
    for run in runs.values():
        assert run["status"].iloc[0] == "completed"
        assert run["test_loss"].iloc[1] < run["test_loss"].iloc[0]  # an eta = 1 HIG step from any start lowers it


def test_summary_reads_each_curve_at_the_checkpoints_and_nan_past_its_end():
    curves = pd.DataFrame({"variant": ["a"] * 3 + ["b"] * 2, "epoch": [0, 1, 2, 0, 1], "updates": [0, 1024, 24_576, 0, 1024],
                           "train_loss": [1.0, 0.1, 0.01, 2.0, 0.2], "test_loss": [1.5, 0.15, 0.02, 2.5, 0.3],
                           "status": "completed", "seconds": 1.0})  # fmt: skip
    table = probe.summary(curves).set_index("variant")
    assert table.loc["a", "test_at_1024"] == 0.15 and table.loc["a", "test_at_24576"] == 0.02
    assert table.loc["b", "test_at_1024"] == 0.3 and math.isnan(table.loc["b", "test_at_24576"])
    assert table.loc["a", "test_at_8192"] == 0.15  # the last evaluation at or before 8,192 updates
