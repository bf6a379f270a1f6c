"""REML fit of  y ~ condition + (1|rater) + (1|clip)  — two crossed random intercepts — from sufficient statistics.

statsmodels' MixedLM can fit crossed effects (one group, variance components), but its optimiser stops at
different points for different methods on our data (REML log-likelihood off by ~0.8). This module profiles the
REML criterion over the two relative variances exactly as lme4 does (Bates et al. 2015, J. Stat. Softw. 67(1),
eqs. 34-42), so a fit is a smooth 2-D bounded minimisation. Every quantity is built from counts and sums —
never an n x q matrix — so the cost depends on the number of raters and clips, not on the number of ratings.

Model: y = X b + Z_r u_r + Z_c u_c + e, u_r ~ N(0, s2 t_r I), u_c ~ N(0, s2 t_c I), e ~ N(0, s2 I).
With V* = I + t_r Z_r Z_r' + t_c Z_c Z_c' and M = I + Lambda Z'Z Lambda (q x q, Lambda = diag(sqrt t)):
  log|V*| = log|M|  and  V*^-1 = I - Z Lambda M^-1 Lambda Z'   (determinant lemma, Woodbury),
  -2 l_R(t) = log|M| + log|X'V*^-1 X| + (n-p) (1 + log(2 pi r2 / (n-p))),  s2 = r2 / (n-p),
where r2 = (y - X b)'V*^-1 (y - X b) at the GLS estimate b. M is solved by eliminating its diagonal
rater block and a dense Cholesky of the clip-block Schur complement (or the other way round if raters are fewer).
"""

import math

import numpy as np
from scipy import linalg, optimize, sparse
from scipy import stats as sps

from moglow_eval.core.blas import one_blas_thread

BOUND_NEAR = 1e-3  # a relative SD this close to 0 sits at the bound, where the polish is needed
# An eigenvalue of the REML deviance's Hessian in the variances at or below this share of the largest is taken as 0:
# the criterion is flat along its direction (a variance the ratings do not identify), whose sampling variation the
# Satterthwaite df then leave out, as lmerTest does, rather than dividing by round-off. The Hessian's central
# differences leave such an eigenvalue at a few times 1e-8 of the largest, not at 0. The ordinal model's information
# matrix, also by central differences, is held to the same rule (ordinal.py).
FLAT_EIGENVALUE = 1e-6
DENSE_MAX = 4_000_000  # raters x clips up to which the count table is held dense (32 MB)
EXACT_FIT = 1e-12  # residual sum of squares, as a share of the total, at which the effects fit every rating


class ModelUndefined(ValueError):
    """The data cannot identify the model (a statement for the report, not a failure)."""


class _Suff:
    """Sufficient statistics of the design: counts per level, the rater x clip count table, X'X, X'y, Z'X, Z'y."""

    def __init__(self, y, X, rater, clip):
        self.n, self.p = X.shape
        self.R, self.C = int(rater.max()) + 1, int(clip.max()) + 1
        ybar = y.mean()
        yc = y - ybar  # centring keeps y'y - ... free of cancellation; the intercept absorbs the shift
        self.ybar = ybar
        self.nr = np.bincount(rater, minlength=self.R).astype(float)
        self.nc = np.bincount(clip, minlength=self.C).astype(float)
        self.N = sparse.csr_matrix((np.ones(self.n), (rater, clip)), shape=(self.R, self.C))
        self.XtX = X.T @ X
        self.Xty = X.T @ yc
        self.yty = float(yc @ yc)
        self.ZrX = np.stack([np.bincount(rater, weights=X[:, j], minlength=self.R) for j in range(self.p)], 1)
        self.ZcX = np.stack([np.bincount(clip, weights=X[:, j], minlength=self.C) for j in range(self.p)], 1)
        self.Zry = np.bincount(rater, weights=yc, minlength=self.R)
        self.Zcy = np.bincount(clip, weights=yc, minlength=self.C)
        # The Schur complement needs A' diag(1 / (1 + t n_big)) A for every trial t. Levels of the eliminated
        # factor with the same count share that weight, so A' D A = sum over distinct counts g of
        # w_g (A_g' A_g): precompute the few A_g' A_g once (a panel where everyone rates everything has one).
        self.rater_big = self.R >= self.C
        self.A = self.N if self.rater_big else self.N.T.tocsr()
        # A panel's count table is small: dense products skip sparse bookkeeping that costs more than the
        # arithmetic, at each of the hundreds of evaluations a fit makes.
        self.A_op = self.A.toarray() if self.R * self.C <= DENSE_MAX else self.A
        n_big = self.nr if self.rater_big else self.nc
        small = min(self.R, self.C)
        counts, which = np.unique(n_big, return_inverse=True)
        self.gram = None
        if len(counts) * small * small <= 40_000_000:
            self.gram_counts = counts
            if isinstance(self.A_op, np.ndarray):
                # Dense rows grouped by their count, one product per contiguous group: a bootstrap resample has
                # dozens of distinct counts, where selecting each group's rows of the sparse table cost more than
                # the fit. The entries are counts, so the sums are exact in any order.
                rows = self.A_op[np.argsort(which, kind="stable")]
                sizes = np.bincount(which, minlength=len(counts))
                self.gram = np.stack([rows[e - n : e].T @ rows[e - n : e] for n, e in zip(sizes, np.cumsum(sizes))])
            else:
                groups = (self.A[which == g] for g in range(len(counts)))  # each group's rows selected once
                self.gram = np.stack([(rows.T @ rows).toarray() for rows in groups])


def additive_rss(s):
    """Residual sum of squares of y ~ X + rater + clip with every effect fixed (least squares), from the sufficient
    statistics `s` (_Suff) the fit is built from: the larger factor's block of the normal equations is diagonal and
    is eliminated, as in the fit, and the rest (the smaller factor's levels and X's columns, singular by the
    intercept they share and by whatever else of X the levels span) is solved by least squares."""
    if s.rater_big:
        n_big, z_big, big_x, n_small, z_small, small_x = s.nr, s.Zry, s.ZrX, s.nc, s.Zcy, s.ZcX
    else:
        n_big, z_big, big_x, n_small, z_small, small_x = s.nc, s.Zcy, s.ZcX, s.nr, s.Zry, s.ZrX
    rest = np.block([[np.diag(n_small), small_x], [small_x.T, s.XtX]])
    z_rest = np.concatenate([z_small, s.Xty])
    # A level with no rating (a bootstrap draws a rater whose clips were all left out) has no part in the fit.
    inv_big = np.divide(1.0, n_big, out=np.zeros_like(n_big), where=n_big > 0)
    # The big factor's dummies against the small one's, then X; dense where the count table is (see _Suff).
    if isinstance(s.A_op, np.ndarray):
        cross = np.hstack([s.A_op, big_x])
        schur = rest - (cross.T * inv_big) @ cross
    else:
        cross = sparse.hstack([s.A, big_x]).tocsr()
        schur = rest - (cross.T @ sparse.diags(inv_big) @ cross).toarray()
    b = linalg.lstsq(schur, z_rest - cross.T @ (z_big * inv_big), check_finite=False)[0]
    a = (z_big - cross @ b) * inv_big
    return max(float(s.yty - a @ z_big - b @ z_rest), 0.0)


def _solve_parts(s, tr, tc):
    """log|M| and a solver for M x = v, with M = [[I + tr diag(nr), a N], [a N', I + tc diag(nc)]]."""
    a = math.sqrt(tr * tc)
    A = s.A  # eliminate the larger block (diagonal), Cholesky of the smaller block's Schur complement
    if s.rater_big:
        d_big, d_small, t_big = 1 + tr * s.nr, 1 + tc * s.nc, tr
    else:
        d_big, d_small, t_big = 1 + tc * s.nc, 1 + tr * s.nr, tc
    if s.gram is not None:
        AtDA = np.tensordot(1 / (1 + t_big * s.gram_counts), s.gram, axes=1) * (a * a)
    else:
        AtDA = (A.T @ sparse.diags(1 / d_big) @ A).toarray() * (a * a)
    schur = np.diag(d_small) - AtDA
    chol = linalg.cho_factor(schur, lower=True, check_finite=False)
    logdet = float(np.log(d_big).sum() + 2 * np.log(np.diag(chol[0])).sum())

    op = s.A_op

    def solve(v_big, v_small):
        rhs = v_small - a * (op.T @ (v_big / d_big[:, None] if v_big.ndim == 2 else v_big / d_big))
        x_small = linalg.cho_solve(chol, rhs, check_finite=False)
        x_big = (v_big - a * (op @ x_small)) / (d_big[:, None] if v_big.ndim == 2 else d_big)
        return x_big, x_small

    return logdet, solve


def _gls(s, tr, tc):
    """For relative variances (tr, tc): REML deviance, b (centred y), X'V*^-1 X and r2."""
    logdet, solve = _solve_parts(s, tr, tc)
    sr, sc = math.sqrt(tr), math.sqrt(tc)
    # Lambda Z'X and Lambda Z'y, split into the eliminated ("big") and Schur ("small") blocks
    LX_r, LX_c, Ly_r, Ly_c = sr * s.ZrX, sc * s.ZcX, sr * s.Zry, sc * s.Zcy
    if s.rater_big:
        bX, sX, by, sy = LX_r, LX_c, Ly_r, Ly_c
    else:
        bX, sX, by, sy = LX_c, LX_r, Ly_c, Ly_r
    xb, xs = solve(np.column_stack([bX, by]), np.column_stack([sX, sy]))
    W = bX.T @ xb[:, :-1] + sX.T @ xs[:, :-1]  # (Lambda Z'X)' M^-1 (Lambda Z'X)
    w = bX.T @ xb[:, -1] + sX.T @ xs[:, -1]
    yy = by @ xb[:, -1] + sy @ xs[:, -1]
    XVX = s.XtX - W
    XVy = s.Xty - w
    yVy = s.yty - yy
    cx = linalg.cho_factor(XVX, lower=True, check_finite=False)
    b = linalg.cho_solve(cx, XVy, check_finite=False)
    r2 = max(float(yVy - b @ XVy), 1e-300)
    dof = s.n - s.p
    dev = logdet + 2 * np.log(np.diag(cx[0])).sum() + dof * (1 + math.log(2 * math.pi * r2 / dof))
    return float(dev), b, XVX, r2


def _reml_deviance(s, varpar):
    """-2 REML log-likelihood at absolute variances (rater, clip, residual), not profiled: the function whose
    curvature gives the sampling covariance of the variance estimates."""
    tr, tc, s2 = varpar[0] / varpar[2], varpar[1] / varpar[2], varpar[2]
    dev_p, _, _, r2 = _gls(s, tr, tc)
    dof = s.n - s.p
    base = dev_p - dof * (1 + math.log(2 * math.pi * r2 / dof))  # log|M| + log|X'V*^-1 X|
    return base + dof * math.log(s2) + r2 / s2 + dof * math.log(2 * math.pi)


def _beta_cov(s, varpar):
    _, _, XVX, _ = _gls(s, varpar[0] / varpar[2], varpar[1] / varpar[2])
    return varpar[2] * linalg.inv(XVX)


def curved(values):
    """Which of a fit's Hessian eigenvalues `values` are above FLAT_EIGENVALUE of the largest: the others are the
    directions the criterion is flat along (here and in ordinal.py)."""
    return values > FLAT_EIGENVALUE * max(np.abs(values).max(), np.finfo(float).tiny)


def satterthwaite_df(s, varpar):
    """Satterthwaite degrees of freedom of each fixed effect, as lmerTest computes them:
    df_k = 2 Var(b_k)^2 / (g_k' A g_k), with g_k the gradient of Var(b_k) in the variance parameters and
    A = 2 H^-1 their asymptotic covariance (H the Hessian of the REML deviance). Both derivatives are central
    differences with steps relative to each variance, Richardson-extrapolated. A variance estimated at 0 sits
    on the boundary and is held fixed there (no sampling variation to propagate). The df are invariant to how
    the variances are parametrised, so (rater, clip, residual) variances give lmerTest's (theta, sigma) df.
    Where H has eigenvalues of about 0 (FLAT_EIGENVALUE) or below, A is its generalised inverse over the others.

    Returns (df [p], the number of such flat directions)."""
    varpar = np.asarray(varpar, float)
    active = np.flatnonzero(varpar > 1e-10 * varpar[2])
    x0 = varpar[active]
    m = len(active)

    def f(v):
        full = varpar.copy()
        full[active] = v
        return _reml_deviance(s, full)

    f0 = f(x0)

    def hessian(h):
        H = np.empty((m, m))
        for i in range(m):
            ei = np.zeros(m)
            ei[i] = h[i]
            H[i, i] = (f(x0 + ei) - 2 * f0 + f(x0 - ei)) / h[i] ** 2
            for j in range(i):
                ej = np.zeros(m)
                ej[j] = h[j]
                H[i, j] = H[j, i] = (f(x0 + ei + ej) - f(x0 + ei - ej) - f(x0 - ei + ej) + f(x0 - ei - ej)) / (
                    4 * h[i] * h[j]
                )
        return H

    def var_gradient(h):
        rows = []
        for i in range(m):
            up, down = varpar.copy(), varpar.copy()
            up[active[i]] += h[i]
            down[active[i]] -= h[i]
            rows.append(np.diag(_beta_cov(s, up) - _beta_cov(s, down)) / (2 * h[i]))
        return np.array(rows)  # [m, p]

    # Richardson extrapolation of the central differences: error O(h^4), so df agree with lmerTest's
    # numDeriv-based ones to ~1e-7 instead of ~1e-4
    h = 2e-3 * x0
    H = (4 * hessian(h / 2) - hessian(h)) / 3
    G = (4 * var_gradient(h / 2) - var_gradient(h)) / 3
    values, vectors = linalg.eigh((H + H.T) / 2)
    kept = curved(values)
    A = 2 * (vectors[:, kept] / values[kept]) @ vectors[:, kept].T
    cov = _beta_cov(s, varpar)
    denom = np.einsum("ip,ij,jp->p", G, A, G)
    with np.errstate(divide="ignore"):  # no direction of curvature at all: nothing to propagate, df infinite
        return 2 * np.diag(cov) ** 2 / denom, int(m - kept.sum())


def fit_crossed(y, X, rater, clip, names, with_cov=False, tests=True, start=None):
    """REML fit. y float [n]; X [n, p] fixed-effects design (first column the intercept); rater, clip int codes.

    Returns dict: fixed_effects, std_errors, df (Satterthwaite), t, p_values (t tests on those df),
    ci_low/ci_high (95%, t on those df), flat_directions (how many directions of the variances the REML criterion
    is flat along, left out of the df: 0 where the ratings identify them all),
    variance_components {rater, clip, residual}, reml_log_likelihood, converged; with `with_cov`, also
    "covariance": the fixed effects' covariance matrix [p, p] (for a joint Wald test of several effects).
    tests=False leaves out df, t, p_values and the intervals (their Satterthwaite df cost a fifth of a fit), for
    a caller that wants only the variances, as a bootstrap of them does. start: the random effects' SDs relative
    to the residual's where the search begins, for a refit near a known estimate (a bootstrap's resample starts
    at the whole sample's); such a refit skips the derivative-free polish unless an SD ends at 0.

    ModelUndefined where the fixed effects with a level per rater and per clip fit every rating exactly.
    """
    # One BLAS thread: the criterion is a chain of small factorisations, where thread hand-offs cost more than
    # they save (far slower on a busy 2-core machine), and the rounding is then identical from run to run.
    with one_blas_thread():
        s = _Suff(np.asarray(y, float), np.asarray(X, float), np.asarray(rater), np.asarray(clip))
        # Ratings that the fixed effects with a level per rater and per clip give exactly: the REML criterion falls
        # without end as the residual variance goes to 0, so there is no estimate, and the search would stop
        # wherever it wandered, among ever larger variances, or at a Hessian of round-off.
        if additive_rss(s) <= EXACT_FIT * s.yty:
            raise ModelUndefined(
                "the fixed effects with a level per rater and per clip fit every rating exactly: no residual "
                "variance to estimate; model undefined"
            )
        fit, cov = _fit(s, names, tests, start)
    return {**fit, "covariance": cov} if with_cov else fit


def _fit(s, names, tests=True, start=None):
    """(fit_crossed's dict, the fixed effects' covariance matrix) from the sufficient statistics `s`."""

    def objective(rel_sd):  # lme4's parameters: random-effect SDs relative to the residual SD, >= 0
        try:
            return _gls(s, rel_sd[0] ** 2, rel_sd[1] ** 2)[0]
        except linalg.LinAlgError:
            # A line search can step to SDs so large that X'V^-1X loses definiteness in floating point (seen on
            # a rater-bootstrap resample); such a point is never the optimum, so it only has to look bad.
            return 1e300

    # Tolerances sit above the float noise of the criterion (~1e-16 x its size), so both stop cleanly.
    best = optimize.minimize(
        objective,
        np.array([0.5, 0.5]) if start is None else np.asarray(start, float),
        method="L-BFGS-B",
        bounds=[(0, None), (0, None)],
        options={"ftol": 1e-13, "gtol": 1e-8, "maxiter": 200},
    )
    # Polish: a derivative-free search from there (robust when an SD sits on the 0 bound, where the
    # finite-difference gradient of L-BFGS-B is one-sided). A refit from a given start (a bootstrap's, from the
    # whole sample's estimate) polishes only where it can matter: at a bound, or where L-BFGS-B did not converge.
    polish = best
    if start is None or not best.success or min(best.x) < BOUND_NEAR:
        polish = optimize.minimize(
            lambda v: objective(np.abs(v)),
            best.x,
            method="Nelder-Mead",
            options={"xatol": 1e-8, "fatol": 1e-9, "maxiter": 600},
        )
    x = np.abs(polish.x) if polish.fun <= best.fun else best.x
    dev, b, XVX, r2 = _gls(s, x[0] ** 2, x[1] ** 2)
    sigma2 = r2 / (s.n - s.p)
    b = b.copy()
    b[0] += s.ybar  # undo the centring (first column is the intercept)
    cov = sigma2 * linalg.inv(XVX)
    se = np.sqrt(np.diag(cov))
    varpar = np.array([sigma2 * x[0] ** 2, sigma2 * x[1] ** 2, sigma2])
    out = {"fixed_effects": dict(zip(names, b.tolist())), "std_errors": dict(zip(names, se.tolist()))}
    if tests:
        df, flat = satterthwaite_df(s, varpar)
        t = b / se
        p = 2 * sps.t.sf(np.abs(t), df)
        q = sps.t.ppf(0.975, df)
        out.update(
            df=dict(zip(names, df.tolist())),
            t=dict(zip(names, t.tolist())),
            p_values=dict(zip(names, p.tolist())),
            ci_low=dict(zip(names, (b - q * se).tolist())),
            ci_high=dict(zip(names, (b + q * se).tolist())),
            flat_directions=flat,
        )
    out.update(
        variance_components={"rater": float(varpar[0]), "clip": float(varpar[1]), "residual": float(sigma2)},
        reml_log_likelihood=-0.5 * dev,
        converged=bool(best.success or polish.success),
    )
    return out, cov
