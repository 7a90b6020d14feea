"""Standard errors: Fisher information and the Cramer-Rao bound.

For Gaussian force noise of standard deviation sigma_j on loop j, the Fisher
information of the parameters is I = J^T diag(1/sigma^2) J with J the Jacobian
of the model force at every sample; the Cramer-Rao bound is I^-1. With the
thesis' (non-ML) loop weights W the least-squares estimator's covariance is the
sandwich (J^T W J)^-1 J^T W Sigma W J (J^T W J)^-1. Where sigma is unknown it is
estimated from the residuals of each loop at the given parameters.

:func:`jacobian_covariance` is the one place a covariance is formed from a
Jacobian of whitened residuals, (J^T J)^-1 with the columns scaled first so
that parameters of very different magnitude (a yield displacement of microns
next to a stiffness of 10^6 N/m) do not ruin the inverse.
"""

from __future__ import annotations

import numpy as np

from hysid_model.objective import Objective


def scaled_inverse(matrix: np.ndarray) -> np.ndarray:
    """The inverse of a symmetric information matrix, scaled to unit diagonal first (pseudo-inverse where
    singular): without the scaling, a pseudo-inverse's cut-off drops the weakly determined directions of
    parameters of very different magnitude and reports them as precise."""
    scale = np.sqrt(np.abs(np.diag(matrix)))
    scale = np.where(scale > 0, scale, 1.0)
    return np.linalg.pinv(matrix / np.outer(scale, scale), hermitian=True) / np.outer(scale, scale)


def jacobian_covariance(jac: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 of a whitened-residual Jacobian ``(N, D)``, column-scaled (pseudo-inverse where singular)."""
    return scaled_inverse(jac.T @ jac)


def noise_sigma(obj: Objective, theta: np.ndarray) -> np.ndarray:
    """Each loop's sigma: the known one, else the residual RMS (dof-corrected)."""
    sigma = obj.loops.sigma.copy()
    unknown = ~(np.isfinite(sigma) & (sigma > 0))
    if np.any(unknown):
        kept = obj.keep.sum(axis=1)  # the samples that count (:attr:`Objective.keep`)
        n_total = int(kept.sum())
        dof_factor = n_total / max(n_total - obj.dim, 1)
        rms = np.sqrt(obj.per_loop_sse(theta) / kept * dof_factor)
        sigma[unknown] = rms[unknown]
    return sigma


def fisher_information(obj: Objective, theta: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
    sigma = noise_sigma(obj, theta) if sigma is None else np.asarray(sigma, dtype=float)
    jac = obj.jacobian(theta, weighted=False)
    inv_var = np.repeat(1.0 / sigma**2, obj.y.shape[1])
    return jac.T @ (jac * inv_var[:, None])


def cramer_rao_stderr(obj: Objective, theta: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
    """sqrt(diag(I^-1)): the smallest standard error any unbiased estimator can reach."""
    return np.sqrt(np.diag(scaled_inverse(fisher_information(obj, theta, sigma))))


def covariance(obj: Objective, theta: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
    """Covariance of the weighted least-squares estimate under the objective's weights."""
    sigma = noise_sigma(obj, theta) if sigma is None else np.asarray(sigma, dtype=float)
    jac = obj.jacobian(theta, weighted=False)
    n = obj.y.shape[1]
    w = np.repeat(obj.loop_weight, n)
    var = np.repeat(sigma**2, n)
    bread = scaled_inverse(jac.T @ (jac * w[:, None]))
    meat = jac.T @ (jac * (w**2 * var)[:, None])
    return bread @ meat @ bread


def standard_errors(obj: Objective, theta: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
    cov = covariance(obj, theta, sigma)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))
