"""Sigma-point Kalman filters (UKF, 3rd- and 5th-degree CKF) over B runs, with the TL update.

A rule approximates E[g(x)], x ~ N(m, P), by sum_s w_s g(m + L xi_s) with L L' = P. The seed's
baselines TL-UKF and TL-CKF (Alotaibi et al. 2024) condition on the primary's z_k and the source's
eta_hat_k at once. Both are Gaussian statements about h(x_k) with independent errors, so they stack
into one measurement [z; eta; ...] with noise blockdiag(Q_w, P_eta_eta, ...): one Kalman update then
serves the isolated, TL, multi-source and centralized-fusion filters alike. A scan with false
alarms and missed detections is then taken by probabilistic data association
(:mod:`~tltrack.filters.association`).

Angles: a bearing mean is ref + sum_s w_s wrap(Z_s - ref), with ref the bearing of the mean state.
Unlike a circular mean, that is right for the 5th-degree rule's negative weights, and it holds
across the +-pi cut. Every measurement difference goes through the sensor's wrapped ``residual``.

The 5th-degree rule's negative weight (n = 5) can make a covariance indefinite. Every covariance is
symmetrised and, if an eigenvalue is <= 0, repaired by clipping; :attr:`SigmaPointFilter.repairs`
counts the repairs per run.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.filters.association import associate
from tltrack.filters.base import Estimate
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan, Statement

Array = NDArray[np.float64]

#: clipped eigenvalues become this fraction of the matrix's largest |eigenvalue|
REL_FLOOR = 1e-12


@dataclass(frozen=True, eq=False)
class SigmaRule:
    """Unit sigma points ``xi`` (n, S) and weights ``w`` (S,) for N(0, I_n)."""

    xi: Array
    w: Array

    @property
    def n(self) -> int:
        return int(self.xi.shape[0])


def unscented(n: int, kappa: float) -> SigmaRule:
    """Julier & Uhlmann (2000), 2n + 1 points.

    The centre, weight kappa/(n+kappa); +-sqrt(n+kappa) e_i, weight 1/(2(n+kappa)).
    """
    if n + kappa <= 0:
        raise ValueError(f"n + kappa must be positive, got {n} + {kappa}")
    c = np.sqrt(n + kappa)
    eye = np.eye(n)
    xi = np.hstack([np.zeros((n, 1)), c * eye, -c * eye])
    w = np.r_[kappa / (n + kappa), np.full(2 * n, 0.5 / (n + kappa))]
    return SigmaRule(xi, w)


def cubature3(n: int) -> SigmaRule:
    """Arasaratnam & Haykin (2009) spherical-radial rule: +-sqrt(n) e_i, weights 1/(2n)."""
    eye = np.eye(n)
    return SigmaRule(np.sqrt(n) * np.hstack([eye, -eye]), np.full(2 * n, 0.5 / n))


def cubature5(n: int) -> SigmaRule:
    """Jia, Xin & Cheng (2013) 5th-degree rule, 2n^2 + 1 points (docs/background.md).

    Centre, weight 2/(n+2); +-sqrt(n+2) e_i, weight (4-n)/(2(n+2)^2), negative for n > 4;
    +-sqrt(n+2)(e_k +- e_l)/sqrt(2) for k < l, weight 1/(n+2)^2.
    """
    c = np.sqrt(n + 2.0)
    eye = np.eye(n)
    pairs = [
        sk * eye[i] + sl * eye[j]
        for i, j in combinations(range(n), 2)
        for sk in (1.0, -1.0)
        for sl in (1.0, -1.0)
    ]
    xi = np.hstack([np.zeros((n, 1)), c * eye, -c * eye, c / np.sqrt(2.0) * np.array(pairs).T])
    d = (n + 2.0) ** 2
    w = np.r_[2.0 / (n + 2.0), np.full(2 * n, (4.0 - n) / (2.0 * d)), np.full(len(pairs), 1.0 / d)]
    return SigmaRule(xi, w)


def _floor(w: Array) -> Array:
    """Per-matrix clipping floor for eigenvalues ``w`` (b, n)."""
    return np.maximum(REL_FLOOR * np.abs(w).max(axis=-1, keepdims=True), np.finfo(float).tiny)


def _make_pd(P: Array) -> tuple[Array, NDArray[np.bool_]]:
    """Symmetrise (b, n, n) covariances and clip eigenvalues <= 0; also which ones were repaired."""
    P = 0.5 * (P + P.swapaxes(-1, -2))
    bad = np.linalg.eigvalsh(P)[:, 0] <= 0.0
    if bad.any():
        w, V = np.linalg.eigh(P[bad])
        Pb = (V * np.maximum(w, _floor(w))[:, None, :]) @ V.swapaxes(-1, -2)
        P[bad] = 0.5 * (Pb + Pb.swapaxes(-1, -2))
    return P, bad


def _sqrt(P: Array) -> tuple[Array, NDArray[np.bool_]]:
    """L with L L' = P per matrix: Cholesky, else V sqrt(clip(w)); also which ones fell back."""
    try:
        return np.linalg.cholesky(P).astype(np.float64), np.zeros(len(P), dtype=np.bool_)
    except np.linalg.LinAlgError:
        pass
    L = np.empty_like(P)
    fell_back = np.zeros(len(P), dtype=np.bool_)
    for b, Pb in enumerate(P):
        try:
            L[b] = np.linalg.cholesky(Pb)
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(Pb)
            L[b] = V * np.sqrt(np.maximum(w, _floor(w[None])[0]))
            fell_back[b] = True
    return L, fell_back


def _wcov(A: Array, C: Array, w: Array) -> Array:
    """sum_s w_s A_s C_s' per run: A (p, b, S), C (q, b, S) -> (b, p, q)."""
    return (A * w).transpose(1, 0, 2) @ C.transpose(1, 2, 0)


def _moments(sensor: MeasurementModel, Z: Array, zref: Array, w: Array) -> tuple[Array, Array]:
    """Weighted mean (n_z, b) of Z (n_z, b, S), taken relative to zref, and deviations from it."""
    zhat = zref + sensor.residual(Z, zref[..., None]) @ w
    zhat = sensor.residual(zhat, np.zeros_like(zhat))  # angles back into their principal range
    return zhat, sensor.residual(Z, zhat[..., None])


def _block_diag(blocks: Sequence[Array]) -> Array:
    """blockdiag of (b, p_j, p_j) blocks -> (b, sum p_j, sum p_j)."""
    sizes = [blk.shape[-1] for blk in blocks]
    out = np.zeros((blocks[0].shape[0], sum(sizes), sum(sizes)))
    start = 0
    for blk, p in zip(blocks, sizes, strict=True):
        out[:, start : start + p, start : start + p] = blk
        start += p
    return out


class SigmaPointFilter:
    """Gaussian filter whose moments come from a sigma-point rule; mean (n_x, B), cov (B, n_x, n_x).

    ``repairs`` (B,) counts, per run, every eigenvalue clipping: of a covariance that was not
    positive-definite, or of a square root whose Cholesky factorisation failed.
    """

    def __init__(self, model: MotionModel, rule: SigmaRule, x0_hat: Array, P0: Array) -> None:
        n, B = x0_hat.shape
        if model.n != n or rule.n != n:
            raise ValueError(f"state dimension {n}, model {model.n}, rule {rule.n}")
        self.model = model
        self.rule = rule
        self.m: Array = np.array(x0_hat, dtype=float)
        self.P: Array = np.broadcast_to(np.asarray(P0, dtype=float), (B, n, n)).copy()
        #: per run, how many covariances had an eigenvalue clipped (the module's docstring)
        self.repairs = np.zeros(B, dtype=np.int64)
        #: per run, log N(nu; 0, S) of the last update's stacked innovation (0: no statement);
        #: an interacting multiple-model filter weighs its modes by it
        self.loglik = np.zeros(B)

    def _points(self, runs: NDArray[np.intp]) -> tuple[Array, Array]:
        """Sigma points X (n, b, S) of the selected runs' (m, P), and their deviations X - m."""
        L, fell_back = _sqrt(self.P[runs])
        self.repairs[runs] += fell_back
        dX = (L @ self.rule.xi).transpose(1, 0, 2)
        return self.m[:, runs, None] + dX, dX

    def _set_cov(self, runs: NDArray[np.intp], P: Array) -> None:
        self.P[runs], repaired = _make_pd(P)
        self.repairs[runs] += repaired

    def predict(self) -> None:
        """m = sum w f(X), P = sum w (f(X) - m)(f(X) - m)' + Q_v: the time update of the UKF/CKF."""
        runs = np.arange(self.m.shape[1])
        w = self.rule.w
        X, _ = self._points(runs)
        Xp = self.model.f(X)
        self.m = Xp @ w
        D = Xp - self.m[..., None]
        self._set_cov(runs, _wcov(D, D, w) + self.model.Q)

    def update(self, observations: Sequence[Statement]) -> None:
        """One stacked Kalman update per run on the Gaussian statements whose mask includes it,
        then one association per scan.

        Runs are grouped by which statements apply to them, so a masked-out statement is absent
        from that run's update, exactly.
        """
        self.loglik = np.zeros(self.m.shape[1])
        gaussian = [o for o in observations if isinstance(o, Observation)]
        if gaussian:
            self._update_gaussian(gaussian)
        for scan in (o for o in observations if isinstance(o, Scan)):
            self._associate(scan)  # after the transfers: its gate is the sharper prior's

    def _update_gaussian(self, observations: Sequence[Observation]) -> None:
        B = self.m.shape[1]
        active = np.array([np.ones(B, bool) if o.mask is None else o.mask for o in observations])
        patterns, group = np.unique(active.T, axis=0, return_inverse=True)
        group = group.ravel()
        for g, pattern in enumerate(patterns):
            if pattern.any():
                used = [observations[int(j)] for j in np.flatnonzero(pattern)]
                self._update_runs(np.flatnonzero(group == g), used)

    def _update_runs(self, runs: NDArray[np.intp], used: Sequence[Observation]) -> None:
        """Condition ``runs`` on the stacked statements [mean_1; mean_2; ...] about h(x)."""
        w = self.rule.w
        X, dX = self._points(runs)
        nus, dZs = [], []
        for obs in used:
            s = obs.sensor
            zhat, dZ = _moments(s, s.h(X), s.h(self.m[:, runs]), w)
            nus.append(s.residual(obs.mean[:, runs], zhat))
            dZs.append(dZ)
        nu, dZ = np.concatenate(nus), np.concatenate(dZs)
        Pzz = _wcov(dZ, dZ, w) + _block_diag([obs.cov[runs] for obs in used])
        Pxz = _wcov(dX, dZ, w)
        K = np.linalg.solve(Pzz, Pxz.swapaxes(-1, -2)).swapaxes(-1, -2)
        _, logdet = np.linalg.slogdet(Pzz)
        d2 = np.einsum("ib,bi->b", nu, np.linalg.solve(Pzz, nu.T[:, :, None])[:, :, 0])
        self.loglik[runs] = -0.5 * (d2 + logdet + nu.shape[0] * np.log(2.0 * np.pi))
        self.m[:, runs] += np.einsum("bij,jb->ib", K, nu)
        self._set_cov(runs, self.P[runs] - K @ Pzz @ K.swapaxes(-1, -2))

    def _associate(self, scan: Scan) -> None:
        """Probabilistic data association of one scan (Bar-Shalom, Daum & Huang 2009, eqs.
        37-44): m += K nu, P -= (1 - beta_0) K S K' - K (sum_j beta_j nu_j nu_j' - nu nu') K'."""
        runs = np.arange(self.m.shape[1])
        w = self.rule.w
        X, dX = self._points(runs)
        s = scan.sensor
        zhat, dZ = _moments(s, s.h(X), s.h(self.m), w)
        S, _ = _make_pd(_wcov(dZ, dZ, w) + scan.cov)
        K = np.linalg.solve(S, _wcov(dX, dZ, w).swapaxes(-1, -2)).swapaxes(-1, -2)
        a = associate(scan, Observation(s, zhat, S))
        Kt = K.swapaxes(-1, -2)
        self.m += np.einsum("bij,jb->ib", K, a.innovation)
        P = self.P - (1.0 - a.beta0)[:, None, None] * (K @ S @ Kt) + K @ a.spread @ Kt
        self._set_cov(runs, P)
        self.loglik += a.loglik

    def estimate(self) -> Estimate:
        """The Gaussian posterior itself: its mean and covariance."""
        return Estimate(self.m.T.copy(), self.P.copy())

    def adopt(self, other: SigmaPointFilter, runs: NDArray[np.bool_]) -> None:
        """``other``'s (m, P) for ``runs`` (the robust TL's rollback to its isolated twin)."""
        self.m[:, runs] = other.m[:, runs]
        self.P[runs] = other.P[runs]

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        """eta_hat = E[h(x)] and P_eta_eta = Cov[h(x)] + R under the current density: a transfer."""
        runs = np.arange(self.m.shape[1])
        w = self.rule.w
        X, _ = self._points(runs)
        eta, dZ = _moments(sensor, sensor.h(X), sensor.h(self.m), w)
        cov, repaired = _make_pd(_wcov(dZ, dZ, w) + R)
        self.repairs += repaired
        return Observation(sensor, eta, cov)


#: the UKF's scaling parameter: the centre's weight is kappa / (n + kappa)
UKF_KAPPA = 2.0
KAPPA = Parameter("kappa", "1", "UKF scaling parameter (Julier & Uhlmann 2000)", default=UKF_KAPPA)


class _RuleKind(SigmaPointFilter, abc.ABC):
    """A filter kind (:mod:`tltrack.filters.kinds`) whose rule depends only on n and its declared
    parameters."""

    kind: ClassVar[str]
    particle: ClassVar[bool] = False
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    @staticmethod
    @abc.abstractmethod
    def rule_for(n: int, params: Mapping[str, float]) -> SigmaRule:
        """The sigma points for a state of dimension n."""

    @classmethod
    def build(
        cls,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        *,
        particles: int,
        rngs: Sequence[np.random.Generator] | None,
        params: Mapping[str, float],
    ) -> SigmaPointFilter:
        return cls(model, cls.rule_for(model.n, params), x0_hat, P0)


class UnscentedKalmanFilter(_RuleKind):
    """``ukf``: the unscented rule, 2n + 1 points."""

    kind = "ukf"
    parameters = (KAPPA,)

    @staticmethod
    def rule_for(n: int, params: Mapping[str, float]) -> SigmaRule:
        return unscented(n, params["kappa"])


class CubatureKalmanFilter3(_RuleKind):
    """``ckf3``: the 3rd-degree spherical-radial cubature rule, 2n points."""

    kind = "ckf3"

    @staticmethod
    def rule_for(n: int, params: Mapping[str, float]) -> SigmaRule:
        return cubature3(n)


class CubatureKalmanFilter5(_RuleKind):
    """``ckf5``: the 5th-degree cubature rule, 2n^2 + 1 points."""

    kind = "ckf5"

    @staticmethod
    def rule_for(n: int, params: Mapping[str, float]) -> SigmaRule:
        return cubature5(n)
