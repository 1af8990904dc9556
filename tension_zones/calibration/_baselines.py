"""Black-box baselines for the report: what a model-free regressor of the commands reaches.

k-nearest neighbours and polynomial ridge regression from the commands (and known loads) to the tip
position (scikit-learn, the ``bench`` extra; ``None`` without it). Their hyper-parameters are chosen
on the same held-out part as the loop's decisions; then they are refitted on all of the training
data and evaluated on the validation file, exactly like the physical model.
"""

from __future__ import annotations

import numpy as np

from ._fits import rmse


def _rmse(a, b) -> float:
    return rmse(np.asarray(a) - np.asarray(b))


def baselines(data, train, held, val) -> dict | None:
    """``{name: {choice, rmse_held_out_mm, rmse_validate_mm, rmse_validate_aligned_mm, predicted}}`` for
    boolean sample masks of ``data`` (a Dataset), or ``None`` without scikit-learn."""
    try:
        from sklearn.linear_model import Ridge
        from sklearn.neighbors import KNeighborsRegressor
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import PolynomialFeatures, StandardScaler
    except ImportError:
        return None
    X = np.c_[data.q, data.f] if np.any(data.f) else np.asarray(data.q)
    y = np.asarray(data.p)
    grids: dict[str, list] = {
        "knn": [
            (
                f"k={k}",
                lambda k=k: make_pipeline(
                    StandardScaler(), KNeighborsRegressor(min(k, int(train.sum())), weights="distance")
                ),
            )
            for k in (1, 3, 5, 10, 20)
        ],
        "poly_ridge": [
            (
                f"degree={d}, alpha={a:g}",
                lambda d=d, a=a: make_pipeline(StandardScaler(), PolynomialFeatures(d), Ridge(alpha=a)),
            )
            for d in (1, 2, 3, 4)
            for a in (1e-3, 1e-1, 10.0)
        ],
    }
    out = {}
    fit_all = train | held
    for name, grid in grids.items():
        scores = [
            (_rmse(make().fit(X[train], y[train]).predict(X[held]), y[held]), label, make) for label, make in grid
        ]
        h, label, make = min(scores, key=lambda s: s[0])
        pv = make().fit(X[fit_all], y[fit_all]).predict(X[val])
        d = pv - y[val]
        out[name] = {
            "choice": label,
            "rmse_held_out_mm": h,
            "rmse_validate_mm": _rmse(pv, y[val]),
            "rmse_validate_aligned_mm": _rmse(d - d.mean(axis=0), 0 * d),
            "predicted": pv,
        }
    return out
