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


@partial(jax.jit, static_argnums=0)
def predict_jit(spec, theta, phys0, inputs):
    return predict_theta(spec, theta, phys0, inputs)


@partial(jax.jit, static_argnums=0)
def residual_jacobian(spec, theta, phys0, inputs, y):
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


@partial(jax.jit, static_argnums=(0, 10))
def lm_fit(spec, theta0, free, w, c, lo, hi, phys0, inputs, y, max_iter=40):
    """Bounded Levenberg-Marquardt with IRLS (Huber) weights, over the free parameters only.

    Args:
        theta0: start (P,); free: 0/1 (P,); w: sample weights (N,) (0 = not in the fit);
        c: Huber threshold on the 3-D residual norm (mm), ``inf`` for least squares;
        lo, hi: bounds (P,), enforced by projection.
    Returns ``(theta, cost, iterations)``.
    """
    freeb = free > 0
    eye = jnp.eye(theta0.shape[0], dtype=theta0.dtype)

    def cost_of(th):
        r = predict_theta(spec, th, phys0, inputs) - y
        return huber_cost(r, w, c)

    def body(state):
        th, lam, cost, it, _ = state
        r, J = residual_jacobian(spec, th, phys0, inputs, y)
        sw = w * huber_weights(r, c)
        J = J * free
        A = jnp.einsum("nip,niq,n->pq", J, J, sw)
        g = jnp.einsum("nip,ni,n->p", J, r, sw)
        d = jnp.diag(A)
        d = jnp.maximum(d, 1e-12 * jnp.max(d) + 1e-300)
        A = A + lam * jnp.diag(d)
        A = jnp.where(freeb[:, None] & freeb[None, :], A, eye)
        step = -jnp.linalg.solve(A, jnp.where(freeb, g, 0.0))
        new = jnp.clip(th + jnp.where(freeb, step, 0.0), lo, hi)
        new_cost = cost_of(new)
        ok = new_cost < cost
        rel = (cost - new_cost) / jnp.maximum(cost, 1e-300)
        done = (ok & (rel < 1e-10)) | (lam > 1e12)
        return (jnp.where(ok, new, th), jnp.where(ok, lam / 3.0, lam * 4.0),
                jnp.where(ok, new_cost, cost), it + 1, done)

    def cond(state):
        return (state[3] < max_iter) & ~state[4]

    state = (theta0, jnp.asarray(1e-3, theta0.dtype), cost_of(theta0), 0, False)
    th, _, cost, it, _ = jax.lax.while_loop(cond, body, state)
    return th, cost, it


class Problem:
    """A model, its blocks and one data set, ready to fit: the concrete edge around the jitted core."""

    def __init__(self, model, design, data, blocks):
        self.model = model
        self.data = data
        self.phys0 = model.physical(design)
        phys_np = jax.tree_util.tree_map(np.asarray, self.phys0)
        sizes = tuple(int(b.size(phys_np)) for b in blocks)
        self.spec = Spec(model=model, blocks=tuple(blocks), sizes=sizes)
        self.inputs = model.inputs(data)
        self.y = jnp.asarray(data.p)
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

    def predict(self, theta) -> np.ndarray:
        return np.asarray(predict_jit(self.spec, jnp.asarray(theta), self.phys0, self.inputs))

    def residuals(self, theta) -> np.ndarray:
        return self.predict(theta) - np.asarray(self.y)

    def jacobian(self, theta):
        r, J = residual_jacobian(self.spec, jnp.asarray(theta), self.phys0, self.inputs, self.y)
        return np.asarray(r), np.asarray(J)

    def fit(self, theta0, active, weights, huber_c=np.inf, max_iter=40) -> np.ndarray:
        theta0 = np.clip(np.asarray(theta0, float), self.lo, self.hi)
        th, _, _ = lm_fit(self.spec, jnp.asarray(theta0), jnp.asarray(self.mask(active)),
                          jnp.asarray(weights, float), jnp.asarray(huber_c, float),
                          jnp.asarray(self.lo), jnp.asarray(self.hi), self.phys0, self.inputs,
                          self.y, max_iter)
        return np.asarray(th)

    def describe(self, theta, names) -> dict:
        """``{block: {label: value}}`` in report units, for the named blocks."""
        out = {}
        sl = self.spec.slices()
        for b in self.spec.blocks:
            if b.name in names:
                vals = b.report_values(np.asarray(theta)[sl[b.name]], self._phys_np)
                out[b.name] = {k: float(v) for k, v in zip(b.labels(self._phys_np), np.ravel(vals))}
        return out
