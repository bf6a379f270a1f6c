"""Cumulative-link (logit) mixed model  rating ~ condition + (1|rater) + (1|clip), fitted as R's ordinal::clmm
does by default: maximum likelihood with the Laplace approximation over crossed random intercepts.

Why an ordinal model: ratings are 1-5 labels, not distances. The linear mixed model treats the step from 1 to 2
as the step from 4 to 5; the cumulative-link model estimates the four cut points instead and reports condition
effects as log-odds of a higher rating, which is what a reviewer of ordinal data asks for.

Model: P(Y <= j | u) = F(theta_j - eta), eta = x'beta + s_r u_r + s_c u_c, u ~ N(0, I), F logistic.
Laplace: log L(phi) = l(y | u*) - u*'u*/2 - log|H|/2, where u* maximises g(u) = l(y | u) - u'u/2 (inner Newton
solve) and H = I + Lambda Z'WZ Lambda is minus the Hessian of g at u* (W = diag(-d2 l_i / d eta_i^2)).

Speed (the whole fit is a few hundred evaluations of log L): H is never formed densely. Its rater and clip
blocks are diagonal and the cross block is the rater x clip table of weights, so the larger factor is
eliminated and only the Schur complement of the smaller one (66 x 66 on a 66-rater study) is factorised. The
outer optimiser gets the exact gradient of the Laplace objective: the envelope term of l, plus the derivative
of log|H|, which needs third derivatives of l and the implicit derivative du*/dphi = H^-1 d2g/du dphi; all of
it reduces to per-rating quantities and the leverages h_i = z_i' H^-1 z_i, so a gradient costs about one more
factorisation, not one log L per parameter.
"""

import math

import numpy as np
from scipy import linalg, optimize
from scipy import stats as sps
from scipy.special import expit

from moglow_eval.core.blas import one_blas_thread

from .mixed import curved


class OrdinalError(ValueError):
    """The data cannot identify the ordinal model (one category, no variation to fit)."""


def _link(theta_ext, y, eta, third=True):
    """Log-probability of each rating and its derivatives in the two cut points a = theta_y - eta (upper) and
    b = theta_{y-1} - eta (lower), to second order (the Newton solve) or third (the gradient of log|H|).
    Infinite cut points (y = 1, y = K) give zero terms. Products, not powers: numpy's float power is two orders
    of magnitude slower than two multiplications, and this runs on every rating in every Newton step."""
    a = theta_ext[y + 1] - eta
    b = theta_ext[y] - eta
    Fa, Fb = expit(a), expit(b)
    Fna, Fnb = expit(-a), expit(-b)
    # P = F(a) - F(b) without cancellation: from the nearer tail
    P = np.maximum(np.where(a + b > 0, Fnb - Fna, Fa - Fb), 1e-300)
    fa, fb = Fa * Fna, Fb * Fnb  # logistic density F(1 - F)
    la, lb = fa / P, -fb / P
    A2, B2 = fa * (Fna - Fa) / P, -fb * (Fnb - Fb) / P  # P_aa / P, P_bb / P (f' = f (1 - 2F))
    laa, lbb, lab = A2 - la * la, B2 - lb * lb, -la * lb
    out = {
        "logp": np.log(P),
        "la": la,
        "lb": lb,
        "laa": laa,
        "lbb": lbb,
        "lab": lab,
        "l_eta": -(la + lb),
        "w": -(laa + 2 * lab + lbb),
    }
    if third:
        A3, B3 = fa * (1 - 6 * fa) / P, -fb * (1 - 6 * fb) / P  # P_aaa / P, P_bbb / P (f'' = f (1 - 6f))
        la2, lb2 = la * la, lb * lb
        laaa = A3 - 3 * A2 * la + 2 * la2 * la
        lbbb = B3 - 3 * B2 * lb + 2 * lb2 * lb
        laab = (2 * la2 - A2) * lb
        labb = (2 * lb2 - B2) * la
        out.update(
            w_eta=laaa + 3 * laab + 3 * labb + lbbb, w_up=-(laaa + 2 * laab + labb), w_low=-(laab + 2 * labb + lbbb)
        )
    return out


class _Design:
    """Codes and index arrays of one data set; the larger random factor is 'big' (eliminated), the other
    'small' (its Schur complement is factorised)."""

    def __init__(self, y, X, rater, clip, n_levels):
        self.y, self.X = y, X
        self.n, self.p = X.shape
        self.K = n_levels
        self.R, self.C = int(rater.max()) + 1, int(clip.max()) + 1
        self.rater, self.clip = rater, clip
        self.rater_big = self.R >= self.C
        self.big, self.small = (rater, clip) if self.rater_big else (clip, rater)
        self.nb, self.ns = (self.R, self.C) if self.rater_big else (self.C, self.R)
        self.cell = self.big * self.ns + self.small
        self.up = np.minimum(y, self.K - 2)  # threshold index in a (valid where y < K - 1)
        self.has_up = y < self.K - 1
        self.low = np.maximum(y - 1, 0)
        self.has_low = y > 0


def _unpack(d, phi):
    th = phi[: d.K - 1]
    beta = phi[d.K - 1 : d.K - 1 + d.p]
    # capped: on data where an SD's likelihood keeps rising (separation by raters or clips) the search may run
    # far out; the caller reports such a fit as not identified instead of overflowing
    s_r, s_c = math.exp(min(phi[-2], 30.0)), math.exp(min(phi[-1], 30.0))
    return th, beta, s_r, s_c


class _Schur:
    """H = I + [[diag(db), B], [B', diag(ds)]] over (big, small) factors, through the Schur complement of the
    small block: S = I + diag(ds) - B' diag(1/(1 + db)) B."""

    def __init__(self, db, ds, B):
        self.dbig = 1 + db
        self.B = B
        self.Bd = B / self.dbig[:, None]
        S = np.diag(1 + ds) - B.T @ self.Bd
        self.chol = linalg.cho_factor(S, lower=True, check_finite=False)
        self.logdet = float(np.log(self.dbig).sum() + 2 * np.log(np.diag(self.chol[0])).sum())

    def solve(self, vb, vs):
        xs = linalg.cho_solve(self.chol, vs - self.Bd.T @ vb, check_finite=False)
        xb = (vb - self.B @ xs) / (self.dbig[:, None] if vb.ndim == 2 else self.dbig)
        return xb, xs

    def blocks(self):
        """diag of H^-1's big block, H^-1's small block, and its big x small block."""
        Sinv = linalg.cho_solve(self.chol, np.eye(self.chol[0].shape[0]), check_finite=False)
        M = self.Bd @ Sinv
        return 1 / self.dbig + np.einsum("ij,ij->i", M, self.Bd), Sinv, -M


class _Laplace:
    """log L and its gradient at phi = (thresholds, betas, log sd_rater, log sd_clip); the random-effect mode
    is kept between calls as the next start (successive optimiser points are close)."""

    def __init__(self, d):
        self.d = d
        self.u = np.zeros(d.R + d.C)
        self.evals = 0

    def _eta(self, beta, s_r, s_c, u):
        d = self.d
        return d.X @ beta + s_r * u[: d.R][d.rater] + s_c * u[d.R :][d.clip]

    def _hessian(self, q, s_r, s_c):
        d = self.d
        w = q["w"]
        hr = s_r * s_r * np.bincount(d.rater, w, d.R)
        hc = s_c * s_c * np.bincount(d.clip, w, d.C)
        B = np.bincount(d.cell, w * (s_r * s_c), d.nb * d.ns).reshape(d.nb, d.ns)
        return _Schur(hr, hc, B) if d.rater_big else _Schur(hc, hr, B)

    def _split(self, v):
        d = self.d
        return (v[: d.R], v[d.R :]) if d.rater_big else (v[d.R :], v[: d.R])

    def _join(self, vb, vs):
        return np.concatenate([vb, vs]) if self.d.rater_big else np.concatenate([vs, vb])

    def mode(self, phi, tol=1e-10, max_iter=100):
        """Newton ascent of g(u) with step halving; g is concave (the logistic cumulative link is log-concave)."""
        d = self.d
        th, beta, s_r, s_c = _unpack(d, phi)
        theta_ext = np.concatenate([[-np.inf], th, [np.inf]])
        u = self.u.copy()
        q = _link(theta_ext, d.y, self._eta(beta, s_r, s_c, u), third=False)
        g = q["logp"].sum() - 0.5 * u @ u
        for _ in range(max_iter):
            grad = (
                np.concatenate(
                    [s_r * np.bincount(d.rater, q["l_eta"], d.R), s_c * np.bincount(d.clip, q["l_eta"], d.C)]
                )
                - u
            )
            H = self._hessian(q, s_r, s_c)
            step = self._join(*H.solve(*self._split(grad)))
            decrement = float(grad @ step)
            t = 1.0
            while True:
                u_new = u + t * step
                q_new = _link(theta_ext, d.y, self._eta(beta, s_r, s_c, u_new), third=False)
                g_new = q_new["logp"].sum() - 0.5 * u_new @ u_new
                if g_new >= g - 1e-12 * abs(g) or t < 1e-8:
                    break
                t *= 0.5
            u, q, g = u_new, q_new, g_new
            if decrement < tol:
                break
        q = _link(theta_ext, d.y, self._eta(beta, s_r, s_c, u))  # third order, at the mode
        H = self._hessian(q, s_r, s_c)
        self.u = u
        return u, q, H, theta_ext

    def value_and_grad(self, phi):
        """-log L and its gradient in phi."""
        self.evals += 1
        d = self.d
        th, beta, s_r, s_c = _unpack(d, phi)
        u, q, H, _ = self.mode(phi)
        ur, uc = u[: d.R][d.rater], u[d.R :][d.clip]
        loglik = q["logp"].sum() - 0.5 * u @ u - 0.5 * H.logdet
        # leverages h_i = z_i' H^-1 z_i, z_i = s_r e_rater + s_c e_clip
        gbb, gss, gbs = H.blocks()
        big, small = d.big, d.small
        g_big, g_small, g_cross = gbb[big], gss[small, small], gbs[big, small]
        s_big, s_small = (s_r, s_c) if d.rater_big else (s_c, s_r)
        h = s_big**2 * g_big + s_small**2 * g_small + 2 * s_big * s_small * g_cross
        g_rr, g_cc = (g_big, g_small) if d.rater_big else (g_small, g_big)
        w, l_eta, w_eta = q["w"], q["l_eta"], q["w_eta"]
        K1 = d.K - 1
        nphi = K1 + d.p + 2
        dg = np.empty(nphi)  # explicit derivative of l
        dlog = np.empty(nphi)  # explicit derivative of log|H|
        cross = np.empty((d.R + d.C, nphi))  # d2 g / du dphi

        def to_u(v_r, v_c):
            return np.concatenate([s_r * np.bincount(d.rater, v_r, d.R), s_c * np.bincount(d.clip, v_c, d.C)])

        for j in range(K1):
            m_up = d.has_up & (d.up == j)
            m_low = d.has_low & (d.low == j)
            dg[j] = q["la"][m_up].sum() + q["lb"][m_low].sum()
            dlog[j] = (h * (np.where(m_up, q["w_up"], 0) + np.where(m_low, q["w_low"], 0))).sum()
            e = np.where(m_up, -(q["laa"] + q["lab"]), 0) + np.where(m_low, -(q["lab"] + q["lbb"]), 0)
            cross[:, j] = to_u(e, e)
        deta = [d.X[:, k] for k in range(d.p)] + [s_r * ur, s_c * uc]
        for k, de in enumerate(deta):
            c = K1 + k
            dg[c] = l_eta @ de
            dlog[c] = (w_eta * h * de).sum()
            cross[:, c] = to_u(-w * de, -w * de)
        # the scale parameters also multiply z_i itself
        cr = K1 + d.p
        dlog[cr] += (w * (2 * s_r * s_r * g_rr + 2 * s_r * s_c * g_cross)).sum()
        dlog[cr + 1] += (w * (2 * s_c * s_c * g_cc + 2 * s_r * s_c * g_cross)).sum()
        cross[: d.R, cr] += s_r * np.bincount(d.rater, l_eta, d.R)
        cross[d.R :, cr + 1] += s_c * np.bincount(d.clip, l_eta, d.C)
        v = to_u(w_eta * h, w_eta * h)  # d log|H| / du
        Gv = self._join(*H.solve(*self._split(v)))
        grad = dg - 0.5 * (dlog + Gv @ cross)
        return -loglik, -grad


def _to_free(d, phi):
    """(theta_1, log increments of the thresholds, rest): keeps the cut points ordered during the search."""
    th = phi[: d.K - 1]
    return np.concatenate([[th[0]], np.log(np.diff(th)), phi[d.K - 1 :]])


def _from_free(d, x):
    th = x[0] + np.concatenate([[0.0], np.cumsum(np.exp(x[1 : d.K - 1]))])
    return np.concatenate([th, x[d.K - 1 :]])


def fit_clmm(y, X, rater, clip, names, n_levels, level_names=None):
    """ML-Laplace fit. y: int category codes 0..n_levels-1 (every level observed); X [n, p] fixed-effects
    design without intercept (the thresholds hold it); rater, clip: int codes; names: the p effect names.

    Returns dict: thresholds, fixed_effects, std_errors, threshold_std_errors, z, p_values, sd_rater, sd_clip,
    log_likelihood, converged, max_abs_gradient, n_evaluations.
    """
    with one_blas_thread():  # small factorisations: threads cost more than they save
        return _fit(
            np.asarray(y, np.int64),
            np.asarray(X, float),
            np.asarray(rater, np.int64),
            np.asarray(clip, np.int64),
            list(names),
            int(n_levels),
            level_names,
        )


def _fit(y, X, rater, clip, names, K, level_names):
    if K < 2:
        raise OrdinalError("every rating is in one category: no threshold can be estimated")
    d = _Design(y, X, rater, clip, K)
    lap = _Laplace(d)
    cum = np.cumsum(np.bincount(y, minlength=K))[:-1] / len(y)
    start = np.concatenate([np.log(cum / (1 - cum)), np.zeros(d.p), np.log([0.5, 0.5])])
    n_th = K - 1

    def objective(x):
        phi = _from_free(d, x)
        val, grad = lap.value_and_grad(phi)
        # chain rule through theta_j = x_0 + sum_{k <= j} exp(x_k)
        gth = grad[:n_th]
        gx = grad.copy()
        tail = np.cumsum(gth[::-1])[::-1]  # sum_{j >= k} dL/dtheta_j
        gx[0] = tail[0]
        gx[1:n_th] = np.exp(x[1:n_th]) * tail[1:]
        return val, gx

    # BFGS from the identity: its first step is long (gradients ~ n) and the inner solve pays for it once, but
    # starting from I / n (or scaling log L by 1 / n) took 60% more evaluations in all on 3k and 100k ratings
    res = optimize.minimize(
        objective, _to_free(d, start), jac=True, method="BFGS", options={"gtol": 1e-7, "maxiter": 500}
    )
    phi = _from_free(d, res.x)
    nll, grad = lap.value_and_grad(phi)
    # observed information by central differences of the exact gradient (clmm: numerical Hessian of log L)
    hess = np.empty((len(phi), len(phi)))
    for k in range(len(phi)):
        step = 1e-5 * max(1.0, abs(phi[k]))
        e = np.zeros(len(phi))
        e[k] = step
        hess[:, k] = (lap.value_and_grad(phi + e)[1] - lap.value_and_grad(phi - e)[1]) / (2 * step)
    hess = (hess + hess.T) / 2
    lap.mode(phi)  # leave the mode at the optimum
    # Where the information has a direction of about no curvature (mixed.curved: a parameter the ratings do not
    # identify, as when each rater rates a clip of their own), its inverse would be round-off: the standard errors
    # are then undefined, as clmm leaves them, and the fit is not called converged.
    values = np.linalg.eigvalsh(hess)
    ok_hess = bool(curved(values).all())
    cov = linalg.inv(hess) if ok_hess else np.full_like(hess, np.nan)
    se = np.sqrt(np.where(np.diag(cov) > 0, np.diag(cov), np.nan))
    th, beta, s_r, s_c = _unpack(d, phi)
    levels = list(level_names) if level_names is not None else [str(k + 1) for k in range(K)]
    th_names = [f"{levels[j]}|{levels[j + 1]}" for j in range(K - 1)]
    b_se = se[n_th : n_th + d.p]
    z = beta / b_se
    max_grad = float(np.max(np.abs(grad)))
    return {
        "thresholds": dict(zip(th_names, th.tolist())),
        "threshold_std_errors": dict(zip(th_names, se[:n_th].tolist())),
        "fixed_effects": dict(zip(names, beta.tolist())),
        "std_errors": dict(zip(names, b_se.tolist())),
        "z": dict(zip(names, z.tolist())),
        "p_values": dict(zip(names, (2 * sps.norm.sf(np.abs(z))).tolist())),
        "sd_rater": s_r,
        "sd_clip": s_c,
        "log_likelihood": -float(nll),
        "converged": bool(max_grad < 1e-3 and ok_hess),
        "max_abs_gradient": max_grad,
        "n_evaluations": lap.evals,
        "random_effects": {"rater": (s_r * lap.u[: d.R]).tolist(), "clip": (s_c * lap.u[d.R :]).tolist()},
    }


def marginal_probabilities(thresholds, eta, sd_total, n_nodes=40):
    """Population-averaged P(Y = j) for linear predictors eta [m] when rater and clip intercepts are drawn
    from N(0, sd_total^2): the model's predicted rating distribution for a new rater on a new clip, the
    quantity to set beside the observed histogram. Gauss-Hermite quadrature. -> [m, K]."""
    z, wq = np.polynomial.hermite_e.hermegauss(n_nodes)
    wq = wq / wq.sum()
    th = np.concatenate([[-np.inf], np.asarray(thresholds, float), [np.inf]])
    lin = np.asarray(eta, float)[:, None] + sd_total * z[None, :]  # [m, nodes]
    cdf = expit(th[None, :, None] - lin[:, None, :])  # [m, K + 1, nodes]
    return (np.diff(cdf, axis=1) * wq).sum(axis=2)
