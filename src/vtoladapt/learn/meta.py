"""Meta-learning a shared basis: each flight's linear weights solved in closed form inside the loss.

The objective is Neural-Fly's (O'Connell et al., Science Robotics 2022, eq. 6 without the
adversarial term): with ``Phi_t(x) = [A_t(x) | phi_net(x; w)]`` (the fixed physics columns ``A``
and the network's ``h`` columns) and the flight's measured specific force ``y``::

    L(w) = mean_t  min_a  (1 / 3 N_t) ( ||y_t - Phi_t a||^2 + sum_k (sigma_y / s_k)^2 (a_k - a0_k)^2 )
           + weight_decay * |W|^2,

a ridge regression per flight (prior mean ``a0`` and std ``s`` per weight: the physics columns'
prior, and ``N(0, net_weight_std^2)`` for the learned ones; ``sigma_y`` the force noise). The
inner minimum is solved exactly (normal equations, one small ``m + h`` system per flight), so the
gradient with respect to the network's outputs is, by the envelope theorem (``dL/da = 0`` at the
solution), ``-(2 / 3 N_t) r a_net^T`` with the residual ``r``; backpropagation through the two
``tanh`` layers is written out below and checked against finite differences by the tests.
L-BFGS (:func:`scipy.optimize.minimize`) minimises ``L`` over the network's weights.

The domain-adversarial term (optional: ``MetaSettings.adversarial = alpha > 0``, ``learn-basis
--adversarial``). Neural-Fly adds a discriminator that tries to tell a flight's condition (there the
wind speed) from ``phi_net(x)``, and trains the network to defeat it, so that ``phi`` carries what all
conditions share and the linear weights carry the condition. Here the discriminator is a linear
softmax classifier of the network's ``3 h`` outputs (standardised), and the network's term is the
*confusion* loss (Tzeng et al., ICCV 2015): the cross-entropy of the classifier's prediction against
the uniform distribution over the ``C`` conditions, minimal (``log C``) when the classifier can no
longer tell them apart::

    L_adv(w) = alpha * mean_t mean_n ( -(1/C) sum_c log softmax_c(D s(phi_net(x_n; w)) + d) ) - alpha log C.

Unlike the negated classification loss of a gradient-reversal layer, it is bounded below with the
classifier held fixed, so L-BFGS can minimise it in rounds: fit the classifier (multinomial logistic
regression, convex, on the current network's outputs), then run ``max_iter / rounds`` L-BFGS
iterations of ``L + L_adv`` with the classifier held, warm-started from the previous round's
weights. A flight's condition is its fan schedule and fan-bearing quadrant when the log says so
(``--fly``), else the flight itself. With ``alpha = 0`` (the default) training is the plain objective
above, in one L-BFGS run: the shipped files were made so. What the term buys is measured in the
docs (``docs/howto/bases.md``, "The adversarial term").

Why no deep-learning framework: the network is small (16 inputs, two hidden layers of 32, 3 h
outputs), the data fit in memory (tens of flights of a few thousand samples), and full-batch
L-BFGS with an exact gradient converges in a few hundred iterations of numpy in a minute or two on
two cores, deterministically for a seed. numpy and scipy are already the package's dependencies,
so training needs no extra install and nothing can pull a GPU wheel.

"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp

from ..bases.netfile import N_FEATURES, forward


@dataclass
class Task:
    """One flight: normalised features ``z`` (N, F), physics columns ``A`` (N, 3, m), measured force ``y`` (N, 3)."""

    z: np.ndarray
    A: np.ndarray
    y: np.ndarray
    name: str = ""
    condition: int = -1     # index of the flight's condition for the adversarial term (-1: the task's own index)


@dataclass(frozen=True)
class MetaSettings:
    """Training settings (recorded in the basis file)."""

    h: int = 4
    hidden: tuple[int, int] = (32, 32)
    sigma_y: float = 0.3            # m/s^2: the force's noise and model error scale in the ridge
    net_weight_std: float = 1.0     # prior std of each learned weight in the per-flight ridge
    weight_decay: float = 1e-4
    max_iter: int = 400
    seed: int = 0
    adversarial: float = 0.0        # alpha of the domain-adversarial (confusion) term; 0: off
    adversarial_rounds: int = 8     # classifier fits, each followed by max_iter / rounds L-BFGS iterations
    discriminator_l2: float = 1e-3  # ridge of the condition classifier's weights


@dataclass
class MetaResult:
    """The trained network's arrays, the per-flight weights and the loss history."""

    arrays: dict
    weights: list = field(default_factory=list)   # per task: the (m + h) weights of the final ridge
    loss: list = field(default_factory=list)
    physics_only_loss: float = float("nan")
    seconds: float = 0.0
    iterations: int = 0
    condition_accuracy: float = float("nan")   # a classifier fitted on the final outputs: fraction of samples
    condition_chance: float = float("nan")     # told right, and the largest condition's share (chance level)


def init_arrays(settings: MetaSettings, rng: np.random.Generator) -> dict:
    """Glorot-uniform weights, zero biases."""
    H1, H2 = settings.hidden
    sizes = [("W1", (H1, N_FEATURES)), ("W2", (H2, H1)), ("W3", (3 * settings.h, H2))]
    out = {}
    for name, (o, i) in sizes:
        lim = np.sqrt(6.0 / (o + i))
        out[name] = rng.uniform(-lim, lim, size=(o, i))
    out["b1"], out["b2"], out["b3"] = np.zeros(H1), np.zeros(H2), np.zeros(3 * settings.h)
    return out


ORDER = ("W1", "b1", "W2", "b2", "W3", "b3")


def flatten(arrays: dict) -> np.ndarray:
    """The network's arrays as one vector (the optimiser's), in :data:`ORDER`."""
    return np.concatenate([arrays[k].ravel() for k in ORDER])


def unflatten(w: np.ndarray, like: dict) -> dict:
    """The inverse of :func:`flatten`, shaped like ``like``."""
    out, i = {}, 0
    for k in ORDER:
        n = like[k].size
        out[k] = w[i:i + n].reshape(like[k].shape)
        i += n
    return out


@dataclass(frozen=True)
class Discriminator:
    """A linear softmax classifier of the condition from the network's standardised outputs."""

    D: np.ndarray      # (C, 3 h)
    d: np.ndarray      # (C,)
    mu: np.ndarray     # (3 h,) output means and spreads at the fit: s = (out - mu) / sd
    sd: np.ndarray

    def log_probabilities(self, out: np.ndarray) -> np.ndarray:
        """``log p(condition | out)`` per sample, (N, C)."""
        logits = ((out - self.mu) / self.sd) @ self.D.T + self.d
        return logits - logsumexp(logits, axis=1, keepdims=True)

    def confusion(self, out: np.ndarray, weight: np.ndarray) -> tuple[float, np.ndarray]:
        """``sum_n weight_n (-(1/C) sum_c log p_nc) - log C`` (>= 0, 0 when every prediction is uniform) and its
        gradient with respect to ``out``."""
        logp = self.log_probabilities(out)
        C = self.D.shape[0]
        value = float(weight @ (-logp.mean(axis=1))) - np.log(C)
        g_logits = weight[:, None] * (np.exp(logp) - 1.0 / C)
        return value, (g_logits @ self.D) / self.sd

    def accuracy(self, out: np.ndarray, labels: np.ndarray) -> float:
        """Fraction of samples whose condition the classifier names."""
        return float(np.mean(np.argmax(self.log_probabilities(out), axis=1) == labels))


def fit_discriminator(out: np.ndarray, labels: np.ndarray, weight: np.ndarray, n_conditions: int,
                      l2: float = 1e-3) -> Discriminator:
    """The classifier that best tells ``labels`` from ``out`` (weighted multinomial logistic regression with a
    ridge on the weights; convex, solved by L-BFGS from zero, so deterministic)."""
    mu = out.mean(axis=0)
    sd = np.maximum(out.std(axis=0), 1e-9)
    s = (out - mu) / sd
    C, k = n_conditions, out.shape[1]
    onehot = np.zeros((len(labels), C))
    onehot[np.arange(len(labels)), labels] = 1.0
    wsum = float(weight.sum())

    def fun(p):
        D, d = p[:C * k].reshape(C, k), p[C * k:]
        logits = s @ D.T + d
        logp = logits - logsumexp(logits, axis=1, keepdims=True)
        val = -float(np.sum(weight[:, None] * onehot * logp)) / wsum + l2 * float(np.sum(D * D))
        g = weight[:, None] * (np.exp(logp) - onehot) / wsum
        return val, np.concatenate([(g.T @ s + 2 * l2 * D).ravel(), g.sum(0)])

    res = minimize(fun, np.zeros(C * k + C), jac=True, method="L-BFGS-B", options={"maxiter": 500, "gtol": 1e-8})
    return Discriminator(D=res.x[:C * k].reshape(C, k), d=res.x[C * k:], mu=mu, sd=sd)


class Objective:
    """``L(w)`` and its gradient over a fixed set of tasks (the arrays concatenated once)."""

    def __init__(self, tasks: list[Task], prior_mean: np.ndarray, prior_std: np.ndarray, settings: MetaSettings):
        self.settings = settings
        self.z = np.concatenate([t.z for t in tasks])
        self.bounds = np.cumsum([0] + [len(t.y) for t in tasks])
        self.A = [t.A for t in tasks]
        self.y = [t.y for t in tasks]
        self.m = tasks[0].A.shape[2]
        h = settings.h
        self.a0 = np.concatenate([prior_mean, np.zeros(h)])
        s = np.concatenate([prior_std, np.full(h, settings.net_weight_std)])
        self.d = (settings.sigma_y / s) ** 2
        # flat (3 N, m) and (3 N,) views for BLAS; the physics block's normal equations do not change: once
        self.A = [np.ascontiguousarray(A.reshape(3 * A.shape[0], A.shape[2])) for A in self.A]
        self.y = [np.ascontiguousarray(y.reshape(-1)) for y in self.y]
        self.AtA = [A.T @ A for A in self.A]
        self.Aty = [A.T @ y for A, y in zip(self.A, self.y)]
        # the adversarial term: each sample's condition (0 .. C-1) and weight 1 / (T N_t) (each flight
        # counts as much as in L); the classifier is held between rounds (None: the term is off)
        raw = np.array([t.condition if t.condition >= 0 else -(i + 1) for i, t in enumerate(tasks)])
        _, codes = np.unique(raw, return_inverse=True)
        self.n_conditions = int(codes.max()) + 1
        self.labels = np.repeat(codes, np.diff(self.bounds))
        self.sample_weight = np.repeat(1.0 / (len(tasks) * np.diff(self.bounds)), np.diff(self.bounds))
        self.discriminator: Discriminator | None = None

    def solve_task(self, t: int, N: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Ridge weights, residual (n, 3) and loss of task ``t`` with network outputs ``N`` (n, 3, h)."""
        A, y, m = self.A[t], self.y[t], self.m
        h = N.shape[2]
        Nf = N.reshape(-1, h)
        k = m + h
        G = np.empty((k, k))
        b = np.empty(k)
        G[:m, :m] = self.AtA[t]
        G[:m, m:] = A.T @ Nf
        G[m:, :m] = G[:m, m:].T
        G[m:, m:] = Nf.T @ Nf
        b[:m] = self.Aty[t]
        b[m:] = Nf.T @ y
        G[np.diag_indices(k)] += self.d
        b += self.d * self.a0
        a = np.linalg.solve(G, b)
        r = y - A @ a[:m] - Nf @ a[m:]
        loss = (r @ r + np.sum(self.d * (a - self.a0) ** 2)) / len(y)
        return a, r.reshape(-1, 3), loss

    def __call__(self, w: np.ndarray, like: dict) -> tuple[float, np.ndarray]:
        arrays = unflatten(w, like)
        h = self.settings.h
        out, (a1, a2) = forward(arrays, self.z)
        N_all = out.reshape(-1, 3, h)
        g_out = np.empty_like(out)
        total = 0.0
        T = len(self.A)
        for t in range(T):
            s, e = self.bounds[t], self.bounds[t + 1]
            a, r, loss = self.solve_task(t, N_all[s:e])
            total += loss / T
            # envelope theorem: d loss / d N[n, r, j] = -(2 / 3 N_t) r[n, r] a_net[j]
            g = (-2.0 / (3 * (e - s) * T)) * r[:, :, None] * a[self.m:][None, None, :]
            g_out[s:e] = g.reshape(e - s, 3 * h)
        if self.discriminator is not None and self.settings.adversarial > 0:
            val, g_adv = self.discriminator.confusion(out, self.sample_weight)
            total += self.settings.adversarial * val
            g_out += self.settings.adversarial * g_adv
        wd = self.settings.weight_decay
        total += wd * sum(float(np.sum(arrays[k] ** 2)) for k in ("W1", "W2", "W3"))
        grads = {"W3": g_out.T @ a2 + 2 * wd * arrays["W3"], "b3": g_out.sum(0)}
        d2 = (g_out @ arrays["W3"]) * (1.0 - a2 * a2)
        grads["W2"] = d2.T @ a1 + 2 * wd * arrays["W2"]
        grads["b2"] = d2.sum(0)
        d1 = (d2 @ arrays["W2"]) * (1.0 - a1 * a1)
        grads["W1"] = d1.T @ self.z + 2 * wd * arrays["W1"]
        grads["b1"] = d1.sum(0)
        return total, flatten(grads)

    def physics_only(self) -> float:
        """The loss with the physics columns alone (the network's columns zero): what the net must beat."""
        total = 0.0
        m = self.m
        for t in range(len(self.A)):
            G = self.AtA[t] + np.diag(self.d[:m])
            a = np.linalg.solve(G, self.Aty[t] + self.d[:m] * self.a0[:m])
            r = self.y[t] - self.A[t] @ a
            total += (r @ r + np.sum(self.d[:m] * (a - self.a0[:m]) ** 2)) / len(self.y[t])
        return total / len(self.A)


def train(tasks: list[Task], prior_mean: np.ndarray, prior_std: np.ndarray, settings: MetaSettings,
          progress=None) -> MetaResult:
    """Fit the shared network to ``tasks`` (L-BFGS on :class:`Objective`), seeded by ``settings.seed``."""
    if not tasks:
        raise ValueError("no flights to train on")
    t0 = time.perf_counter()
    rng = np.random.default_rng(settings.seed)
    like = init_arrays(settings, rng)
    obj = Objective(tasks, np.asarray(prior_mean, float), np.asarray(prior_std, float), settings)
    history: list[float] = []

    def fun(w):
        val, g = obj(w, like)
        history.append(val)
        if progress is not None:
            progress(len(history), val)
        return val, g

    options = {"maxiter": settings.max_iter, "maxcor": 20, "ftol": 1e-12, "gtol": 1e-9}
    w = flatten(like)
    if settings.adversarial > 0 and obj.n_conditions > 1:
        rounds = max(1, min(settings.adversarial_rounds, settings.max_iter))
        iterations = 0
        for r in range(rounds):
            out, _ = forward(unflatten(w, like), obj.z)
            obj.discriminator = fit_discriminator(out, obj.labels, obj.sample_weight, obj.n_conditions,
                                                  settings.discriminator_l2)
            budget = settings.max_iter // rounds + (1 if r < settings.max_iter % rounds else 0)
            res = minimize(fun, w, jac=True, method="L-BFGS-B", options=dict(options, maxiter=budget))
            w, iterations = res.x, iterations + int(res.nit)
        obj.discriminator = None
        history.append(obj(w, like)[0])   # the last entry: the meta-learning loss alone, as without the term
    else:
        res = minimize(fun, w, jac=True, method="L-BFGS-B", options=options)
        w, iterations = res.x, int(res.nit)
    arrays = unflatten(w, like)
    out, _ = forward(arrays, obj.z)
    N_all = out.reshape(-1, 3, settings.h)
    weights = [obj.solve_task(t, N_all[obj.bounds[t]:obj.bounds[t + 1]])[0] for t in range(len(tasks))]
    # how well the condition can still be told from the trained outputs (with or without the term)
    accuracy = chance = float("nan")
    if obj.n_conditions > 1:
        accuracy = fit_discriminator(out, obj.labels, obj.sample_weight, obj.n_conditions,
                                     settings.discriminator_l2).accuracy(out, obj.labels)
        chance = float(np.bincount(obj.labels).max() / len(obj.labels))
    return MetaResult(arrays={k: np.array(v) for k, v in arrays.items()}, weights=weights, loss=history,
                      physics_only_loss=obj.physics_only(), seconds=time.perf_counter() - t0,
                      iterations=iterations, condition_accuracy=accuracy, condition_chance=chance)
