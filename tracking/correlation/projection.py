"""Adaptive dimensionality reduction, thesis chapter 4 (Algorithm 4.1)."""

from __future__ import annotations

import numpy as np


class AdaptiveProjection:
    """The projection matrix ``B_t`` of Algorithm 4.1, updated once per frame.

    ``B_t`` (``D1 x D2``, orthonormal columns) maximises eq. 4.8,
    ``tr(B^T R_t B)`` with ``R_t = (1 - mu) Q_{t-1} + mu C_t`` (eq. 4.9 with the weights of §4.3):
    the current appearance's covariance ``C_t`` plus the covariances reconstructed from the
    previous projections, so the subspace follows the target while changing slowly enough for
    the learnt coefficients to stay valid (the smoothness term, eq. 4.5-4.6).

    Parameters
    ----------
    dim:
        D2, the number of output dimensions. Clamped to the feature count at the first update.
    mu:
        The learning rate mu (§4.3: 0.1 for a linear kernel, 0.15 otherwise). ``mu = 1`` uses
        only the current appearance; ``mu = 0`` keeps the first frame's projection.
    """

    def __init__(self, dim: int, mu: float) -> None:
        if dim < 1:
            raise ValueError(f"dim must be >= 1, got {dim}")
        if not 0.0 <= mu <= 1.0:
            raise ValueError(f"mu must be in [0, 1], got {mu}")
        self.dim = dim
        self.mu = mu
        self.basis: np.ndarray | None = None
        self.eigenvalues: np.ndarray | None = None
        self._q: np.ndarray | None = None

    def update(self, appearance: np.ndarray) -> np.ndarray:
        """Compute ``B_t`` from the learnt appearance ``x_hat^t`` (Algorithm 4.1).

        Parameters
        ----------
        appearance:
            The learnt appearance, unwindowed, shape ``(M, N, D1)``.

        Returns
        -------
        ndarray, float32, shape ``(D1, D2)``
        """
        samples = appearance.reshape(-1, appearance.shape[-1]).astype(np.float64)
        centred = samples - samples.mean(axis=0)  # lines 1-2: the mean carries no structure
        covariance = centred.T @ centred / samples.shape[0]  # C_t
        previous = self._q  # Q_{t-1}; None at t = 1
        # R_t = C_t at t = 1, else (1 - mu) Q_{t-1} + mu C_t   (lines 3-7)
        r = covariance if previous is None else (1.0 - self.mu) * previous + self.mu * covariance
        eigenvalues, eigenvectors = np.linalg.eigh(r)  # ascending
        keep = min(self.dim, samples.shape[1])
        order = np.argsort(eigenvalues)[::-1][:keep]
        basis = eigenvectors[:, order]  # line 9: B_t
        lam = np.clip(eigenvalues[order], 0.0, None)  # line 10: Lambda_t
        reconstructed = (basis * lam) @ basis.T  # B_t Lambda_t B_t^T
        # Q_t = B Lambda B^T at t = 1, else (1 - mu) Q_{t-1} + mu B Lambda B^T   (lines 11-15)
        self._q = (
            reconstructed
            if previous is None
            else (1.0 - self.mu) * previous + self.mu * reconstructed
        )
        self.basis = basis.astype(np.float32)
        self.eigenvalues = lam
        return self.basis


def block_projection(
    sample: np.ndarray, layout: tuple[tuple[str, int], ...], dims: dict[str, int]
) -> np.ndarray:
    """A block-diagonal projection of feature channels, fixed from one sample (ECO's
    factorised convolution initialised by PCA, Danelljan et al. 2017, §3.1).

    Each block of ``layout`` (``(component, dimensions)`` in stacking order) named in ``dims``
    is projected onto the ``dims[name]`` principal components of its centred channels in
    ``sample`` (``(M, N, D)``); the other blocks pass unchanged. Per block, because the
    components' scales differ: one PCA over all channels would keep the loudest component.

    Returns
    -------
    ndarray, float32, ``(D, D')``: multiply feature vectors by it on the right.
    """
    columns = []
    start = 0
    flat = sample.reshape(-1, sample.shape[-1]).astype(np.float64)
    for name, size in layout:
        keep = min(dims.get(name, size), size)
        block = np.zeros((flat.shape[1], keep))
        if keep == size:
            block[start : start + size] = np.eye(size)
        else:
            channels = flat[:, start : start + size]
            centred = channels - channels.mean(axis=0)
            eigenvalues, eigenvectors = np.linalg.eigh(centred.T @ centred)
            block[start : start + size] = eigenvectors[:, np.argsort(eigenvalues)[::-1][:keep]]
        columns.append(block)
        start += size
    return np.concatenate(columns, axis=1).astype(np.float32)
