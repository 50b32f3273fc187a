"""Covariances of means over independent samples (paths, or blocks of quasi-random paths: engine/core/qmc.py)."""

from __future__ import annotations

import numpy as np


def sample_cov(
    n: np.ndarray, n_samples: np.ndarray, s1: np.ndarray, s2: np.ndarray, q1: np.ndarray, q0: np.ndarray
) -> np.ndarray:
    """Covariance (..., Q, Q) of the mean per path H = s1 / n from B = n_samples independent samples, sample b
    holding n_b paths with sums S_b (..., Q): s2 = sum S_b S_b^T, q1 = sum n_b S_b, q0 = sum n_b^2;
        Cov(H) = B / (B - 1) sum_b (S_b - n_b H)(S_b - n_b H)^T / n^2
               = B / (B - 1) (s2 - H q1^T - q1 H^T + q0 H H^T) / n^2
    (the ratio estimator's variance over clusters of unequal size, Cochran 1977, ch. 9A). One-path samples
    (n_b = 1) give (s2 - n H H^T) / (n (n - 1)). Zero with no path; NaN with one sample."""
    nn, bb = n.astype(float)[..., None], n_samples.astype(float)[..., None, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(nn > 0, s1 / np.maximum(nn, 1.0), 0.0)
        hq = h[..., :, None] * q1[..., None, :]
        r = s2 - hq - np.swapaxes(hq, -1, -2) + q0[..., None, None] * h[..., :, None] * h[..., None, :]
        cov = bb / np.maximum(bb - 1, 1) * r / np.maximum(nn, 1.0)[..., None] ** 2
    return np.where(bb >= 2, cov, np.where(bb > 0, np.nan, 0.0))


def per_path_s2(
    n: np.ndarray, n_samples: np.ndarray, s1: np.ndarray, s2: np.ndarray, q1: np.ndarray, q0: np.ndarray
) -> np.ndarray:
    """The sum of per-path outer products (..., Q, Q) that independent paths would need to give the same
    covariance of the mean as the samples (`sample_cov`): n H H^T + n (n - 1) Cov(H); the samples' own s2
    where every sample is one path, so per-path formulas (metrics.delay_metrics) stay valid for blocks."""
    nn = n.astype(float)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(nn > 0, s1 / np.maximum(nn, 1.0), 0.0)
        eff = nn[..., None] * h[..., :, None] * h[..., None, :] + (nn * (nn - 1))[..., None] * sample_cov(
            n, n_samples, s1, s2, q1, q0
        )
    return np.where((n_samples == n)[..., None, None], s2, eff)


def mean_cov(n: np.ndarray, s1: np.ndarray, s2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean of per-path vectors (..., Q) and the covariance of that mean (..., Q, Q), from n, sums, sums of
    outer products. Zero with no path (adds nothing when estimators combine); NaN covariance with one path."""
    nn = n.astype(float)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.where(nn > 0, s1 / np.maximum(nn, 1.0), 0.0)
        cov = (
            (s2 - nn[..., None] * mu[..., :, None] * mu[..., None, :])
            / np.maximum(nn - 1, 1)[..., None]
            / np.maximum(nn, 1)[..., None]
        )
    n3 = nn[..., None]
    return mu, np.where(n3 >= 2, cov, np.where(n3 > 0, np.nan, 0.0))
