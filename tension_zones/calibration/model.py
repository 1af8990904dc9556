"""A model with effects, as one flat parameter vector, and its robust Levenberg-Marquardt fit.

The loop is model-agnostic. A *model* is any hashable object with

* ``physical(design) -> phys``: the declared physical parameters, a dict pytree;
* ``inputs(data) -> inputs``: per-sample arrays (sample axis first) derived from a ``Dataset``;
* ``predict(phys, inputs) -> (N, 3)``: tip positions for all samples;

(:class:`~tension_zones.calib.forward.SegmentModel` is the single-segment one). Effects
(:mod:`.effects`) transform ``phys``, then ``inputs``, then the predicted positions. Every block
(nominal parameters and every candidate) is always present in the compiled function; a 0/1 mask
over the parameter vector says which are free, the rest stay at their null values. So one
compilation serves the whole loop, and new values or another active set never recompile.
"""

from __future__ import annotations

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np


@dataclasses.dataclass(frozen=True)
class Spec:
    """The static part: a model and its blocks (nominal first), with their sizes."""

    model: object
    blocks: tuple
    sizes: tuple

    @property
    def offsets(self):
        return tuple(int(x) for x in np.cumsum((0,) + self.sizes)[:-1])

    def slices(self):
        return {b.name: slice(o, o + s) for b, o, s in zip(self.blocks, self.offsets, self.sizes)}


def _split(spec: Spec, theta):
    return [theta[o:o + s] for o, s in zip(spec.offsets, spec.sizes)]


def predict_theta(spec: Spec, theta, phys0, inputs):
    """Tip positions (N, 3) for the parameter vector ``theta`` (all blocks applied, in stages)."""
    parts = _split(spec, theta)
    phys = phys0
    for blk, th in zip(spec.blocks, parts):
        phys = blk.on_params(th, phys)
    for blk, th in zip(spec.blocks, parts):
        inputs = blk.on_inputs(th, inputs)
    pos = spec.model.predict(phys, inputs)
    for blk, th in zip(spec.blocks, parts):
        pos = blk.on_outputs(th, pos)
    return pos


def _residual_jacobian(spec, theta, phys0, inputs, y):
    """Residuals (N, 3) and their Jacobian (N, 3, P) with respect to every parameter (forward mode)."""
    fn = lambda th: predict_theta(spec, th, phys0, inputs) - y  # noqa: E731
    return fn(theta), jax.jacfwd(fn)(theta)


def huber_weights(r, c):
    """IRLS weights of the Huber loss on each sample's 3-D residual norm (``c = inf``: least squares)."""
    n = jnp.sqrt(jnp.sum(r * r, axis=-1) + 1e-300)
    return jnp.where(n <= c, 1.0, c / n)


def huber_cost(r, w, c):
    n = jnp.sqrt(jnp.sum(r * r, axis=-1))
    rho = jnp.where(n <= c, 0.5 * n * n, c * n - 0.5 * c * c)
    return jnp.sum(w * rho)


@partial(jax.jit, static_argnums=0)
def engine(spec, theta0, free, w, c, lo, hi, phys0, inputs, y, max_iter):
    """Bounded Levenberg-Marquardt with IRLS (Huber) weights over the free parameters, then the
    residuals and Jacobian at the result: the one compiled function of the loop (``max_iter = 0``
    just evaluates, so predictions and score tests need no compilation of their own).

    Args:
        theta0: start (P,); free: 0/1 (P,); w: sample weights (N,) (0 = not in the fit);
        c: Huber threshold on the 3-D residual norm (mm), ``inf`` for least squares;
        lo, hi: bounds (P,), enforced by projection; max_iter: iteration limit (traced).
    Returns ``(theta, cost, iterations, residuals (N, 3), Jacobian (N, 3, P))``.
    """
    freeb = free > 0
    eye = jnp.eye(theta0.shape[0], dtype=theta0.dtype)

    def propose(th, r, J, lam):
        sw = w * huber_weights(r, c)
        J = J * free
        A = jnp.einsum("nip,niq,n->pq", J, J, sw)
        g = jnp.einsum("nip,ni,n->p", J, r, sw)
        d = jnp.diag(A)
        d = jnp.maximum(d, 1e-12 * jnp.max(d) + 1e-300)
        A = jnp.where(freeb[:, None] & freeb[None, :], A + lam * jnp.diag(d), eye)
        step = -jnp.linalg.solve(A, jnp.where(freeb, g, 0.0))
        return jnp.clip(th + jnp.where(freeb, step, 0.0), lo, hi)

    # One model evaluation per pass (a single copy of the model in the compiled program): evaluate
    # the candidate, accept it if it lowers the cost (the first pass always does), propose the next.
    def body(state):
        th, r, J, cost, cand, lam, it, _ = state
        r_c, J_c = _residual_jacobian(spec, cand, phys0, inputs, y)
        cost_c = huber_cost(r_c, w, c)
        ok = cost_c < cost
        rel = (cost - cost_c) / jnp.maximum(jnp.abs(cost), 1e-300)
        done = (ok & (rel < 1e-10)) | (lam > 1e12)
        th, r, J = (jnp.where(ok, a, b) for a, b in ((cand, th), (r_c, r), (J_c, J)))
        cost = jnp.where(ok, cost_c, cost)
        lam = jnp.where(it == 0, lam, jnp.where(ok, lam / 3.0, lam * 4.0))
        return th, r, J, cost, propose(th, r, J, lam), lam, it + 1, done

    def cond(state):
        return (state[6] <= max_iter) & ~state[7]

    P = theta0.shape[0]
    r0 = jnp.zeros_like(y)
    state = (theta0, r0, jnp.zeros(y.shape + (P,), y.dtype), jnp.asarray(jnp.inf, y.dtype), theta0,
             jnp.asarray(1e-3, y.dtype), 0, False)
    th, r, J, cost, _, _, it, _ = jax.lax.while_loop(cond, body, state)
    return th, cost, it, r, J


#: Sample counts are padded up to a multiple of this (padding repeats the last sample at zero weight,
#: after the real ones, so path-dependent state is untouched): sets of similar size share one compilation.
PAD = 64


def _pad(data):
    """The data set with every per-sample array padded (a ``Dataset`` stays a ``Dataset``)."""
    n = data.n_samples
    extra = (-n) % PAD

    def rep(a):
        return np.concatenate([a, np.repeat(a[-1:], extra, axis=0)])

    changes = {f.name: rep(np.asarray(getattr(data, f.name))) for f in dataclasses.fields(data)
               if isinstance(getattr(data, f.name), np.ndarray) and getattr(data, f.name).shape[:1] == (n,)}
    return dataclasses.replace(data, **changes)


class Problem:
    """A model, its blocks and one data set, ready to fit: the concrete edge around the jitted core."""

    def __init__(self, model, design, data, blocks):
        self.model = model
        self.data = data
        self.n = data.n_samples
        padded = _pad(data)
        self.phys0 = model.physical(design)
        phys_np = jax.tree_util.tree_map(np.asarray, self.phys0)
        sizes = tuple(int(b.size(phys_np)) for b in blocks)
        self.spec = Spec(model=model, blocks=tuple(blocks), sizes=sizes)
        self.inputs = model.inputs(padded)
        self.y = jnp.asarray(padded.p)
        self.n_padded = self.n + (-self.n) % PAD
        self.null = np.concatenate([b.null(phys_np) for b in blocks])
        self.lo = np.concatenate([b.bounds(phys_np)[0] for b in blocks])
        self.hi = np.concatenate([b.bounds(phys_np)[1] for b in blocks])
        self._phys_np = phys_np

    @property
    def names(self):
        return [b.name for b in self.spec.blocks]

    def mask(self, active) -> np.ndarray:
        """0/1 over the parameter vector: the blocks named in ``active`` are free."""
        m = np.zeros(self.null.shape[0])
        sl = self.spec.slices()
        for name in active:
            m[sl[name]] = 1.0
        return m

    def _run(self, theta0, active, weights, huber_c, max_iter):
        theta0 = np.clip(np.asarray(theta0, float), self.lo, self.hi)
        w = np.zeros(self.n_padded)
        w[: self.n] = weights  # padded samples never count
        out = engine(self.spec, jnp.asarray(theta0), jnp.asarray(self.mask(active)), jnp.asarray(w),
                     jnp.asarray(huber_c, float), jnp.asarray(self.lo), jnp.asarray(self.hi), self.phys0,
                     self.inputs, self.y, jnp.asarray(max_iter))
        th, cost, it, r, J = (np.asarray(x) for x in out)
        return th, cost, it, r[: self.n], J[: self.n]

    def jacobian(self, theta):
        """Residuals (N, 3) and Jacobian (N, 3, P) at ``theta``."""
        _, _, _, r, J = self._run(theta, [], np.zeros(self.n), np.inf, 0)
        return r, J

    def residuals(self, theta) -> np.ndarray:
        return self.jacobian(theta)[0]

    def predict(self, theta) -> np.ndarray:
        return self.residuals(theta) + np.asarray(self.y)[: self.n]

    def fit(self, theta0, active, weights, huber_c=np.inf, max_iter=40) -> np.ndarray:
        """Fit the blocks named in ``active`` (the others stay where ``theta0`` has them)."""
        return self._run(theta0, active, weights, huber_c, max_iter)[0]

    def describe(self, theta, names) -> dict:
        """``{block: {label: value}}`` in report units, for the named blocks."""
        out = {}
        sl = self.spec.slices()
        for b in self.spec.blocks:
            if b.name in names:
                vals = b.report_values(np.asarray(theta)[sl[b.name]], self._phys_np)
                out[b.name] = {k: float(v) for k, v in zip(b.labels(self._phys_np), np.ravel(vals))}
        return out

    def describe_std(self, theta, names, std) -> dict:
        """Standard deviations ``std`` (P,) of the parameters, in report units (each block's report
        transform is elementwise, so its slope converts them)."""
        out = {}
        sl = self.spec.slices()
        theta = np.asarray(theta, float)
        for b in self.spec.blocks:
            if b.name in names:
                th, sd = theta[sl[b.name]], np.asarray(std)[sl[b.name]]
                h = 1e-6 * np.maximum(np.abs(th), 1.0)
                slope = (np.ravel(b.report_values(th + h, self._phys_np))
                         - np.ravel(b.report_values(th - h, self._phys_np))) / (2 * h)
                out[b.name] = {k: float(v) for k, v in zip(b.labels(self._phys_np), np.abs(slope) * sd)}
        return out


def parameter_std(J, r, free, weights) -> np.ndarray:
    """Linearised standard deviations (P,) of the free parameters (0 for the others).

    ``cov = s^2 (J' W J)^-1`` over the free columns, ``s^2`` the residual variance per axis with the
    degrees of freedom of the fit; a pseudo-inverse so a pair that trades off shows large deviations
    instead of failing.
    """
    cols = np.flatnonzero(np.asarray(free) > 0)
    w = np.asarray(weights, float)
    Jf = (J[:, :, cols] * np.sqrt(w)[:, None, None]).reshape(-1, len(cols))
    rw = (r * np.sqrt(w)[:, None]).ravel()
    dof = max(int(3 * np.count_nonzero(w)) - len(cols), 1)
    s2 = float(rw @ rw) / dof
    std = np.zeros(J.shape[-1])
    std[cols] = np.sqrt(np.maximum(np.diag(np.linalg.pinv(Jf.T @ Jf)) * s2, 0.0))
    return std

