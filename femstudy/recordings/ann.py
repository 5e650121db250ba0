"""The thesis's small neural network (§3.2.2, §5.4–5.5) as an alternative predictor.

Inputs (f [mm/s], N [rpm], z) → outputs (F [N], T [N·mm]); one hidden layer of tanh
neurons (Matlab's default "tansig" sigmoid) and a linear output layer; inputs and targets
mapped to [−1, 1] (Matlab's mapminmax). Training is Levenberg–Marquardt least squares
(``scipy.optimize.least_squares(method="lm")`` with the analytic Jacobian), as Matlab's
default ``trainlm``. Of the 500 training samples (§5.4) 70 % train the weights and 15 % pick
the best of a few random starts, standing in for Matlab's early stopping; the last 15 % are
the test share. MSE values are in the [−1, 1]-scaled outputs, as Matlab reports them.

The neuron study (§5.4.1, Figs 5-12/5-13) trains networks of 1–10 hidden neurons and
compares their training error with the error on held-out runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize

from femstudy.errors import require

SAMPLES = 500
RESTARTS = 3
#: Cap on LM function evaluations per start (Matlab trainlm stops at 1000 epochs, usually far earlier).
MAX_EPOCHS = 300


@dataclass(frozen=True)
class Network:
    """A trained 3-n-2 network with its input and output scaling."""

    hidden: int
    weights: np.ndarray
    x_range: tuple[np.ndarray, np.ndarray]
    y_range: tuple[np.ndarray, np.ndarray]

    def predict(self, X) -> np.ndarray:
        """Outputs (F [N], T [N·mm]) for rows (f, N, z)."""
        Y = _forward(self.weights, self.hidden, _scale(np.asarray(X, float), *self.x_range))
        lo, hi = self.y_range
        return lo + (Y + 1) * (hi - lo) / 2


def _scale(A, lo, hi):
    return 2 * (A - lo) / np.where(hi > lo, hi - lo, 1.0) - 1


def _unpack(w, n):
    W1 = w[: 3 * n].reshape(n, 3)
    b1 = w[3 * n: 4 * n]
    W2 = w[4 * n: 6 * n].reshape(2, n)
    return W1, b1, W2, w[6 * n: 6 * n + 2]


def _forward(w, n, X):
    W1, b1, W2, b2 = _unpack(w, n)
    return np.tanh(X @ W1.T + b1) @ W2.T + b2


def _jacobian(w, n, X):
    """d(outputs, flattened sample-major)/d(weights)."""
    W1, b1, W2, _ = _unpack(w, n)
    H = np.tanh(X @ W1.T + b1)                       # m × n
    dH = 1 - H ** 2
    m = X.shape[0]
    J = np.zeros((m, 2, w.size))
    for k in range(2):
        G = dH * W2[k]                               # m × n: d y_k / d(net_j)
        J[:, k, : 3 * n] = (G[:, :, None] * X[:, None, :]).reshape(m, 3 * n)
        J[:, k, 3 * n: 4 * n] = G
        J[:, k, 4 * n + k * n: 4 * n + (k + 1) * n] = H
        J[:, k, 6 * n + k] = 1.0
    return J.reshape(2 * m, w.size)


def train(X, Y, hidden: int, seed: int = 0) -> tuple[Network, float]:
    """Train a network; returns it and its training MSE (scaled outputs)."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    require(X.shape[0] >= 20, f"the network needs at least 20 training samples, got {X.shape[0]}")
    x_range = (X.min(axis=0), X.max(axis=0))
    y_range = (Y.min(axis=0), Y.max(axis=0))
    Xs, Ys = _scale(X, *x_range), _scale(Y, *y_range)
    rng = np.random.default_rng(seed)
    order = rng.permutation(X.shape[0])
    n_train, n_val = int(0.7 * X.shape[0]), int(0.15 * X.shape[0])
    tr, va = order[:n_train], order[n_train:n_train + n_val]
    n_weights = 6 * hidden + 2
    best, best_val = None, np.inf
    for _ in range(RESTARTS):
        w0 = rng.uniform(-1, 1, n_weights) * np.repeat([1.0, 1.0, 1.0 / np.sqrt(hidden), 0.1],
                                                        [3 * hidden, hidden, 2 * hidden, 2])
        sol = optimize.least_squares(lambda w: (_forward(w, hidden, Xs[tr]) - Ys[tr]).ravel(), w0,
                                     jac=lambda w: _jacobian(w, hidden, Xs[tr]), method="lm",
                                     max_nfev=MAX_EPOCHS)
        val = float(np.mean((_forward(sol.x, hidden, Xs[va]) - Ys[va]) ** 2)) if va.size else sol.cost
        if val < best_val:
            best, best_val = sol.x, val
    net = Network(hidden, best, x_range, y_range)
    return net, mse(net, X[tr], Y[tr])


def mse(net: Network, X, Y) -> float:
    """Mean squared error in the network's [−1, 1]-scaled outputs."""
    P = _scale(net.predict(X), *net.y_range)
    return float(np.mean((P - _scale(np.asarray(Y, float), *net.y_range)) ** 2))


def samples(runs, n: int = SAMPLES, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Up to n (f, N, z) → (F, T) samples drawn evenly from the runs' cuts (seeded)."""
    rng = np.random.default_rng(seed)
    X, Y = [], []
    per_run = max(1, n // max(len(runs), 1))
    for run in runs:
        k = np.sort(rng.choice(run.z.size, size=min(per_run, run.z.size), replace=False))
        X.append(np.column_stack([np.full(k.size, run.feed_mm_s), np.full(k.size, run.spindle_rpm), run.z[k]]))
        Y.append(np.column_stack([run.thrust_N[k], run.torque_Nmm[k]]))
    return np.concatenate(X), np.concatenate(Y)


def run_inputs(run) -> tuple[np.ndarray, np.ndarray]:
    """All (f, N, z) → (F, T) of one run."""
    X = np.column_stack([np.full(run.z.size, run.feed_mm_s), np.full(run.z.size, run.spindle_rpm), run.z])
    return X, np.column_stack([run.thrust_N, run.torque_Nmm])


@dataclass(frozen=True)
class NeuronStudy:
    """Training and held-out MSE for each hidden-layer size; ``best`` minimises the held-out MSE."""

    neurons: list[int]
    training_mse: list[float]
    validation_mse: list[float]
    networks: list[Network]

    @property
    def best(self) -> Network:
        return self.networks[int(np.argmin(self.validation_mse))]


def neuron_study(train_runs, validation_runs, neurons=range(1, 11), seed: int = 0) -> NeuronStudy:
    """Figs 5-12/5-13: networks of 1–10 neurons trained on ``train_runs``, tested on the others."""
    require(len(validation_runs) > 0, "the neuron study needs held-out runs")
    X, Y = samples(train_runs, seed=seed)
    Xv = np.concatenate([run_inputs(r)[0] for r in validation_runs])
    Yv = np.concatenate([run_inputs(r)[1] for r in validation_runs])
    nets, tr, va = [], [], []
    for n in neurons:
        net, train_mse = train(X, Y, n, seed=seed + n)
        nets.append(net)
        tr.append(train_mse)
        va.append(mse(net, Xv, Yv))
    return NeuronStudy(list(neurons), tr, va, nets)
