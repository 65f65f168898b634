"""``check_jacobians``: a factor's analytic Jacobians against central differences.

For an extension's ``gtsam.CustomFactor`` (or any noise-model factor): the whitened Jacobian
blocks GTSAM's ``linearize`` returns at ``values`` are compared with central differences of
``whitenedError`` along each variable's tangent space (``Values.retract``, the same
retraction the solvers use), one column at a time. Use it with a Gaussian noise model: a
robust model re-weights the linearisation but not ``whitenedError``.

A ``CustomFactor`` callback that fills a Jacobian of the wrong shape crashes GTSAM's C++ (a
segmentation fault in ``linearize``, measured with gtsam 4.3). ``factor_shapes`` therefore
evaluates the factor once through ``unwhitenedError(values, H)`` with a Python-owned
``gtsam.JacobianVector`` (GTSAM only copies the callback's matrices into it) and checks the
shapes before anything linearises: a wrong one is a one-line ValueError naming the variable.
``check_jacobians`` does it first, and the smoothers do it for every extension factor at the
initial values (``extend.collect``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np

from ....types.streams import FloatArray


@dataclass(frozen=True)
class JacobianCheck:
    """Per key (``gtsam.DefaultKeyFormatter`` name): the analytic block, the numerical one,
    and the largest absolute difference relative to max(1, |numerical|)."""

    analytic: dict[str, FloatArray]
    numerical: dict[str, FloatArray]
    max_error: dict[str, float]
    tol: float

    @property
    def ok(self) -> bool:
        return all(e <= self.tol for e in self.max_error.values())

    def __str__(self) -> str:
        worst = max(self.max_error, key=self.max_error.get) if self.max_error else None
        return ("Jacobians match central differences" if self.ok else
                f"Jacobian of {worst} differs from central differences by "
                f"{self.max_error[worst]:.3g} (tolerance {self.tol:g})")


def check_jacobians(factor: Any, values: Any, eps: float = 1e-6, tol: float = 1e-5,
                    error_func: Any = None) -> JacobianCheck:
    """Compare ``factor``'s Jacobians at ``values`` with central differences (module
    docstring). ``eps``: the tangent step; ``tol``: the largest accepted difference, relative
    to max(1, |entry|); ``error_func``: the ``CustomFactor`` callback, called once more on its
    own (the factor's shapes are checked by ``factor_shapes`` in any case)."""
    keys = list(factor.keys())
    dims = values.dims()
    if error_func is not None:
        check_shapes(factor, values, error_func)
    try:
        factor_shapes(factor, values)
    except ValueError as exc:
        raise ValueError(f"check_jacobians: {exc}") from None
    lin = factor.linearize(values)
    a_full, _ = lin.jacobian()
    analytic, numerical, err = {}, {}, {}
    col = 0
    for key in keys:
        n = int(dims[key])
        name = gtsam.DefaultKeyFormatter(key)
        if col + n > a_full.shape[1]:
            raise ValueError(f"check_jacobians: the factor's Jacobian has {a_full.shape[1]} "
                             f"columns, fewer than its variables' dimensions ({name})")
        a = a_full[:, col:col + n]
        col += n
        num = np.empty_like(a)
        for j in range(n):
            dv = np.zeros(n)
            dv[j] = eps
            plus, minus = gtsam.VectorValues(), gtsam.VectorValues()
            for k in keys:
                z = np.zeros(int(dims[k]))
                plus.insert(k, dv if k == key else z)
                minus.insert(k, -dv if k == key else z)
            e_p = factor.whitenedError(_retract(values, keys, plus))
            e_m = factor.whitenedError(_retract(values, keys, minus))
            num[:, j] = (e_p - e_m) / (2.0 * eps)
        analytic[name], numerical[name] = a, num
        err[name] = float(np.max(np.abs(a - num) / np.maximum(1.0, np.abs(num)))) if a.size \
            else 0.0
    if col != a_full.shape[1]:
        raise ValueError(f"check_jacobians: the factor's Jacobian has {a_full.shape[1]} "
                         f"columns, its variables {col}")
    return JacobianCheck(analytic, numerical, err, tol)


def _retract(values: Any, keys: list[int], delta: Any) -> Any:
    """``values`` with the factor's keys moved by ``delta`` (the other keys unchanged)."""
    full = gtsam.VectorValues()
    dims = values.dims()
    for k in values.keys():
        full.insert(k, delta.at(k) if k in keys else np.zeros(int(dims[k])))
    return values.retract(full)


def check_shapes(factor: Any, values: Any, error_func: Any) -> None:
    """Call a ``CustomFactor`` callback with Jacobians requested and check that it returns an
    error of the noise model's dimension and fills each Jacobian as (that dimension, the
    variable's tangent dimension); a one-line ValueError names what is wrong."""
    keys = list(factor.keys())
    dims = values.dims()
    h: list[Any] = [None] * len(keys)
    e = np.atleast_1d(np.asarray(error_func(factor, values, h), dtype=float))
    m = int(factor.dim())
    if e.shape != (m,):
        raise ValueError(f"check_jacobians: the error has shape {e.shape}, the noise model "
                         f"dimension is {m}")
    for k, blk in zip(keys, h, strict=True):
        want = (m, int(dims[k]))
        got = None if blk is None else np.shape(blk)
        if got != want:
            raise ValueError(f"check_jacobians: the Jacobian of {gtsam.DefaultKeyFormatter(k)} "
                             f"has shape {got}, expected {want}")


def factor_shapes(factor: Any, values: Any) -> None:
    """Evaluate a noise-model factor once at ``values`` with Jacobians requested, outside
    GTSAM's linearisation, and check the error's length (the noise model's dimension) and
    each Jacobian's shape (that dimension, the variable's tangent dimension); a one-line
    ValueError names what is wrong. Factors without ``unwhitenedError`` (not noise-model
    factors) and inactive ones are not checked."""
    if not hasattr(factor, "unwhitenedError") or not factor.active(values):
        return
    keys = list(factor.keys())
    dims = values.dims()
    jac = gtsam.JacobianVector()
    for _ in keys:
        jac.append(np.zeros((0, 0)))
    e = np.asarray(factor.unwhitenedError(values, jac), dtype=float)
    m = int(factor.dim())
    if e.shape != (m,):
        raise ValueError(f"the error has shape {e.shape}, the noise model dimension is {m}")
    for k, blk in zip(keys, jac, strict=True):
        want = (m, int(dims[k]))
        if np.shape(blk) != want:
            raise ValueError(f"the Jacobian of {gtsam.DefaultKeyFormatter(k)} has shape "
                             f"{np.shape(blk)}, expected {want}")
