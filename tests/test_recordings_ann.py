"""The neural network (thesis §3.2.2, §5.4): gradients, fitting, the neuron study."""

import numpy as np
import pytest

from femstudy.recordings import Effects, synthesize
from femstudy.recordings.ann import _forward, _jacobian, mse, neuron_study, train
from femstudy.recordings.processing import process


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    w, X = rng.normal(size=6 * 3 + 2), rng.normal(size=(7, 3))
    J = _jacobian(w, 3, X)
    numeric = np.column_stack([(_forward(w + d, 3, X) - _forward(w - d, 3, X)).ravel() / 2e-6
                               for d in np.eye(w.size) * 1e-6])
    np.testing.assert_allclose(J, numeric, atol=1e-8)


def test_a_small_network_learns_a_smooth_exponential_map():
    rng = np.random.default_rng(2)
    X = np.column_stack([rng.uniform(1, 2, 400), rng.uniform(1000, 1500, 400), rng.uniform(0, 2, 400)])
    Y = np.column_stack([30 * X[:, 0] * np.exp(0.5 * X[:, 2]), 20 * np.exp(0.4 * X[:, 2]) - 1e-2 * X[:, 1]])
    net, train_mse = train(X, Y, hidden=3, seed=1)
    assert train_mse < 1e-3
    assert mse(net, X, Y) < 2e-3
    assert net.predict(X[:5]) == pytest.approx(Y[:5], rel=0.05)


def test_neuron_study_reports_training_and_held_out_errors():
    train_runs = [process(synthesize(f, n, seed=s, effects=Effects.none())).for_fitting()
                  for s, (f, n) in enumerate([(1.0, 1000), (1.5, 1100), (1.5, 1250), (1.75, 1500), (2.0, 1000)])]
    held = [process(synthesize(1.75, 1250, seed=9, effects=Effects.none())).for_fitting()]
    study = neuron_study(train_runs, held, neurons=range(1, 4))
    assert study.neurons == [1, 2, 3] and len(study.validation_mse) == 3
    assert all(np.isfinite(study.training_mse)) and all(v > 0 for v in study.validation_mse)
    assert study.training_mse[2] < study.training_mse[0]
    assert study.best.hidden in (1, 2, 3)
