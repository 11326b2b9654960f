"""1-D weighted least squares along the track: chainage and receiver clock.

The reference estimator against which SATHIA is compared. With the antenna on its path
``x(s)`` the pseudoranges are ``rho_k = |x(s) - S_k| + b + e_k`` (``b = c dt_rx``, metres), two
unknowns ``(s, b)``. Gauss-Newton along the track, weights ``1 / sigma_k**2``; the design row of
satellite ``k`` is ``[-u_k . t, 1]`` (``u`` unit antenna -> satellite, ``t`` the tangent). The
covariance ``(H^T W H)^-1`` gives ``sigma_s`` and the 1-D protection ``k sigma_s``.

Residual diagnostics for fault detection (:mod:`locator.fde`): ``chi2 = r^T W r`` with
``n - 2`` degrees of freedom, and normalised residuals ``r_k / sqrt((Q_r)_kk)`` with the
residual covariance ``Q_r = W^-1 - H (H^T W H)^-1 H^T`` (Baarda's w-test).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc

from locator.kernels import wls_kernel
from locator.sathia import AntennaPath
from predisat.readonly import freeze_array_fields

__all__ = ["WlsSolution", "as_observations", "solve_wls"]


@dataclass(frozen=True)
class WlsSolution:
    """Result of :func:`solve_wls`.

    Attributes
    ----------
    chainage_m : float
    clock_m : float
        Receiver clock ``c dt``, metres.
    covariance : ndarray, shape (2, 2)
        Of ``(chainage_m, clock_m)``, m**2.
    residual_m : ndarray, shape (n_sat,)
        ``rho - |x(s) - S| - b`` at the solution.
    normalised_residual : ndarray, shape (n_sat,)
        ``residual / sqrt(Q_r[k, k])``; NaN where the residual is not redundant.
    chi2 : float
        ``sum(residual**2 / sigma**2)``.
    dof : int
        ``n_sat - 2``.
    iterations : int
    converged : bool
    at_end : bool
        The solution sits on a track end (clamped there).
    """

    chainage_m: float
    clock_m: float
    covariance: NDArray
    residual_m: NDArray
    normalised_residual: NDArray
    chi2: float
    dof: int
    iterations: int
    converged: bool
    at_end: bool

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def sigma_chainage_m(self) -> float:
        return float(np.sqrt(self.covariance[0, 0]))

    def protection_m(self, k_sigma: float = 2.0) -> float:
        """Half width of the 1-D protection interval, ``k sigma_s``, metres."""
        return k_sigma * self.sigma_chainage_m

    def p_value(self) -> float:
        """Probability of a chi-square this large without a fault (NaN when ``dof < 1``)."""
        return float(chdtrc(self.dof, self.chi2)) if self.dof >= 1 else float("nan")


def as_observations(
    sat_ecef_m: ArrayLike, pseudorange_m: ArrayLike, sigma_m: ArrayLike
) -> tuple[NDArray, NDArray, NDArray]:
    """One epoch's satellites (n_sat, 3), pseudoranges and sigmas (n_sat,) as float arrays.

    Raises
    ------
    ValueError
        When the shapes disagree; the message gives them.
    """
    sat = np.asarray(sat_ecef_m, float)
    rho = np.asarray(pseudorange_m, float)
    sig = np.asarray(sigma_m, float)
    if sat.ndim != 2 or sat.shape[1] != 3 or rho.shape != (len(sat),) or sig.shape != rho.shape:
        raise ValueError(
            "sat_ecef_m must be (n_sat, 3) and pseudorange_m, sigma_m (n_sat,): got "
            f"{sat.shape}, {rho.shape}, {sig.shape}"
        )
    return sat, rho, sig


def solve_wls(
    path: AntennaPath,
    sat_ecef_m: ArrayLike,
    pseudorange_m: ArrayLike,
    sigma_m: ArrayLike,
    *,
    prior_m: float,
    max_iter: int = 20,
    tol_m: float = 1e-4,
) -> WlsSolution:
    """Weighted least-squares chainage and clock of one epoch.

    Parameters
    ----------
    path : AntennaPath
    sat_ecef_m : array_like, shape (n_sat, 3)
    pseudorange_m, sigma_m : array_like, shape (n_sat,)
        Corrected pseudoranges and their sigmas, metres; ``n_sat >= 2``.
    prior_m : float
        Starting chainage. Gauss-Newton converges from hundreds of metres away on real
        geometry; on a track that winds back on itself it may find the wrong branch, so start
        from the previous fix or from SATHIA.
    max_iter : int
    tol_m : float
        Stop when the chainage step is below this.

    Returns
    -------
    WlsSolution
    """
    sat, rho, sig = as_observations(sat_ecef_m, pseudorange_m, sigma_m)
    n = len(rho)
    if n < 2:
        raise ValueError(f"solve_wls needs at least 2 satellites, got {n}")
    if not (np.isfinite(sat).all() and np.isfinite(rho).all() and np.all(sig > 0)):
        raise ValueError("sat_ecef_m / pseudorange_m must be finite and sigma_m positive")
    length = path.length_m
    x, dx = path.hermite_table
    # compiled (locator.kernels): the same arithmetic as the numpy code it replaced (BLAS and
    # LAPACK calls spelled out), bit for bit
    s, b, cov, res, nres, chi2, it, converged, singular = wls_kernel(
        x, dx, float(length), np.ascontiguousarray(sat), np.ascontiguousarray(rho),
        np.ascontiguousarray(sig), float(prior_m), int(max_iter), float(tol_m),
    )  # fmt: skip
    if singular:
        raise np.linalg.LinAlgError("Singular matrix")
    return WlsSolution(
        chainage_m=s,
        clock_m=b,
        covariance=cov,
        residual_m=res,
        normalised_residual=nres,
        chi2=float(chi2),
        dof=n - 2,
        iterations=it,
        converged=converged,
        at_end=bool(s <= 0.0 or s >= length),
    )
