"""Chapter 01a companion: the Kalman filter's experiments, figures and explorer.

Each experiment is a pure function returning numbers (tested without a notebook); each
figure draws one of them. The filter's equations themselves live in
:mod:`annslam_lib.slam.kalman`.
"""
from __future__ import annotations

import math

import numpy as np
from ipywidgets import FloatSlider, interactive

from .. import _checks
from ..models.uncertainty import ellipse_points
from ..plots.style import BLUE, GREEN, ORANGE, RED, figure, show_widget_figure, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam import kalman
from ..slam.kalman import joseph_covariance, kalman_gain

__all__ = ["setup", "one_d_example", "one_d_figure", "random_walk", "random_walk_figure",
           "position_velocity_example", "position_velocity_figure", "suboptimal_gain",
           "same_covariance", "gate_coverage", "range_example", "linearisation_figure",
           "update_summary", "draw_update", "update_explorer", "UPDATE_FIGSIZE"]

#: The explorer's figure size (inches).
UPDATE_FIGSIZE = (7.5, 3.4)


def _grid(lo: float, hi: float, step: float = 0.01) -> np.ndarray:
    return np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)


# ----------------------------------------------------------------------------- section 1

def one_d_example(mu0=10.0, var0=0.25, u=2.0, q=0.09, z=12.4, r=0.16) -> dict:
    """One prediction and one update of a car on a straight road (section 1), by the
    closed forms and by the Bayes filter on a grid (no Gaussian assumption); returns both,
    and the largest difference between them."""
    mu_p, var_p = kalman.predict_1d(mu0, var0, u, q)
    mu_u, var_u, K = kalman.update_1d(mu_p, var_p, z, r)
    g = _grid(mu0 - 8.0, mu0 + u + 8.0)
    prior = kalman.gaussian_pdf(g, mu0, var0)
    pred = kalman.grid_predict(prior, g, u, q)
    post = kalman.grid_update(pred, g, z, r)
    mp, mu_ = kalman.grid_moments(pred, g), kalman.grid_moments(post, g)
    return {"mu0": mu0, "var0": var0, "u": u, "q": q, "z": z, "r": r,
            "predicted": (mu_p, var_p), "posterior": (mu_u, var_u), "K": K,
            "grid": g, "grid_densities": (prior, pred, post),
            "grid_predicted": (mp["mean"], mp["var"]), "grid_posterior": (mu_["mean"], mu_["var"]),
            "max_difference": max(abs(mp["mean"] - mu_p), abs(mp["var"] - var_p),
                                  abs(mu_["mean"] - mu_u), abs(mu_["var"] - var_u))}


def one_d_figure(ex: dict):
    """The four densities of :func:`one_d_example`: closed forms as lines, the grid's
    Bayes filter as dots on top."""
    fig, ax = figure(height=3.6)
    g = ex["grid"]
    prior, pred, post = ex["grid_densities"]
    show = (g > ex["mu0"] - 2.0) & (g < ex["mu0"] + ex["u"] + 2.5)
    curves = [("prior N(%.1f, %.2f)" % (ex["mu0"], ex["var0"]), ex["mu0"], ex["var0"], "0.5", prior),
              ("predicted", *ex["predicted"], BLUE, pred),
              ("GPS likelihood", ex["z"], ex["r"], ORANGE, None),
              ("posterior", *ex["posterior"], GREEN, post)]
    for label, m, v, color, dens in curves:
        ax.plot(g[show], kalman.gaussian_pdf(g[show], m, v), color=color, lw=2,
                ls="--" if dens is None else "-", label=f"{label}: σ = {math.sqrt(v):.2f} m")
        if dens is not None:
            ax.plot(g[show][::40], dens[show][::40], ".", color="k", ms=3)
    ax.plot([], [], ".", color="k", label="Bayes filter on a grid")
    ax.set(xlabel="position along the road [m]", ylabel="density [1/m]",
           title="a prediction widens, an update narrows")
    ax.legend(loc="upper left")
    ax.grid(True, alpha=0.3)
    return fig


# ----------------------------------------------------------------------------- section 2

def random_walk(n_steps=30, u=1.0, q=0.09, r=0.16, mu0=0.0, var0=1.0, seed=1) -> dict:
    """A car moving ``u`` per step with process noise ``q``, measured with noise ``r`` each
    step (seeded). The Kalman filter's prior and posterior means and variances, the grid
    Bayes filter's posterior moments, and the stationary variances of eq. 1a.9."""
    n_steps = _checks.integer("n_steps", n_steps, lo=1)
    rng = np.random.default_rng(seed)
    truth = mu0 + rng.normal(0.0, math.sqrt(var0)) + np.cumsum(u + rng.normal(0.0, math.sqrt(q), n_steps))
    z = truth + rng.normal(0.0, math.sqrt(r), n_steps)
    g = _grid(mu0 - 6.0, mu0 + u * n_steps + 6.0, 0.02)
    dens = kalman.gaussian_pdf(g, mu0, var0)
    mu, var = mu0, var0
    rows = []
    for k in range(n_steps):
        mu_p, var_p = kalman.predict_1d(mu, var, u, q)
        mu, var, K = kalman.update_1d(mu_p, var_p, z[k], r)
        dens = kalman.grid_update(kalman.grid_predict(dens, g, u, q), g, z[k], r)
        m = kalman.grid_moments(dens, g)
        rows.append((mu_p, var_p, mu, var, K, m["mean"], m["var"]))
    a = np.array(rows)
    p_minus, p_plus = kalman.steady_state_variance(q, r)
    return {"truth": truth, "z": z, "prior_mean": a[:, 0], "prior_var": a[:, 1],
            "mean": a[:, 2], "var": a[:, 3], "K": a[:, 4], "grid_mean": a[:, 5],
            "grid_var": a[:, 6], "p_minus": p_minus, "p_plus": p_plus, "q": q, "r": r,
            "max_grid_difference": float(max(np.max(np.abs(a[:, 5] - a[:, 2])),
                                             np.max(np.abs(a[:, 6] - a[:, 3]))))}


def random_walk_figure(walk: dict):
    """Left: truth, measurements and the filter's mean with its 2-sigma band (error
    against truth). Right: the variance before and after each update settling at eq.
    1a.9's stationary values."""
    fig, (ax0, ax1) = figure(1, 2, height=3.6)
    k = np.arange(1, walk["z"].size + 1)
    sd = np.sqrt(walk["var"])
    ax0.fill_between(k, -2 * sd, 2 * sd, color=GREEN, alpha=0.2, label="filter ±2σ")
    ax0.plot(k, walk["z"] - walk["truth"], "x", color=ORANGE, ms=5, label="measurement − truth")
    ax0.plot(k, walk["mean"] - walk["truth"], "o-", color=GREEN, ms=3, label="estimate − truth")
    ax0.axhline(0, color="k", lw=0.6)
    ax0.set(xlabel="step", ylabel="error [m]", title="errors against the truth")
    ax0.legend(loc="lower right")
    saw_k = np.repeat(k, 2)
    saw_v = np.column_stack([walk["prior_var"], walk["var"]]).ravel()
    ax1.plot(saw_k, saw_v, color=BLUE, lw=1.2, label="variance: predict ↑, update ↓")
    ax1.axhline(walk["p_minus"], color=BLUE, ls=":", label=f"p− = {walk['p_minus']:.4f}")
    ax1.axhline(walk["p_plus"], color=GREEN, ls=":", label=f"p+ = {walk['p_plus']:.4f}")
    ax1.set(xlabel="step", ylabel="variance [m²]", yscale="log", title="where the variance settles")
    ax1.legend()
    for ax in (ax0, ax1):
        ax.grid(True, alpha=0.3)
    return fig


# ----------------------------------------------------------------------------- section 3

def position_velocity_example(dt=1.0, sigma_a=0.5, r=4.0, n_steps=5, z_next=None,
                              seed=2) -> dict:
    """A car's (position, velocity) predicted with a constant-velocity model
    (F = [[1, dt], [0, 1]], Q from a random acceleration of sd ``sigma_a``) and measured by
    GPS position only (H = [1, 0], noise ``r``) for ``n_steps`` steps; then one more
    prediction and update, with the gain's velocity entry: the velocity is corrected
    although it is never measured, through P's off-diagonal term."""
    F = np.array([[1.0, dt], [0.0, 1.0]])
    G = np.array([[0.5 * dt * dt], [dt]])
    Q = G @ G.T * sigma_a**2
    H = np.array([[1.0, 0.0]])
    R = np.array([[r]])
    rng = np.random.default_rng(seed)
    truth = np.array([0.0, 5.0])
    x, P = np.array([0.0, 0.0]), np.diag([r, 10.0**2])
    for _ in range(n_steps):
        truth = F @ truth + (G * rng.normal(0, sigma_a)).ravel()
        x, P = kalman.kf_predict(x, P, F, Q)
        x, P = kalman.kf_update(x, P, truth[:1] + rng.normal(0, math.sqrt(r), 1), H, R)
    truth = F @ truth + (G * rng.normal(0, sigma_a)).ravel()
    x_prior, P_prior = kalman.kf_predict(x, P, F, Q)
    z = truth[:1] + rng.normal(0, math.sqrt(r), 1) if z_next is None else np.atleast_1d(z_next)
    K, S = kalman_gain(P_prior, H, R)
    x_post, P_post = kalman.kf_update(x_prior, P_prior, z, H, R)
    corr = P_prior[0, 1] / math.sqrt(P_prior[0, 0] * P_prior[1, 1])
    return {"F": F, "Q": Q, "H": H, "R": R, "truth": truth, "z": z, "x_prior": x_prior,
            "P_prior": P_prior, "K": K, "S": S, "x_post": x_post, "P_post": P_post,
            "correlation": corr}


def position_velocity_figure(ex: dict):
    """The 2-sigma ellipses of (position, velocity) before and after the GPS update."""
    fig, ax = figure(height=3.8)
    for x, P, color, label in [(ex["x_prior"], ex["P_prior"], BLUE, "predicted"),
                               (ex["x_post"], ex["P_post"], GREEN, "after the GPS fix")]:
        e = ellipse_points(x, P, 2.0)
        ax.plot(*e.T, color=color, label=f"{label} (2σ)")
        ax.plot(*x, "o", color=color)
    ax.axvline(float(ex["z"][0]), color=ORANGE, ls="--", label="GPS position")
    ax.plot(*ex["truth"], "k*", ms=10, label="truth")
    ax.set(xlabel="position [m]", ylabel="velocity [m/s]",
           title="a position fix also corrects the velocity (correlation %+.2f)" % ex["correlation"])
    ax.legend()
    ax.grid(True, alpha=0.3)
    return fig


def suboptimal_gain(scale=0.5, n_draws=200_000, seed=3) -> dict:
    """Section 3's "what happens if": the update x+ = x + K (z − H x) with a gain
    ``scale`` times the optimal one, on the position-velocity example. The covariance of
    the error after the update, from ``n_draws`` seeded draws (an independent Monte-Carlo
    estimate), against the Joseph form and the simple form (I − K H) P."""
    ex = position_velocity_example()
    P, H, R = ex["P_prior"], ex["H"], ex["R"]
    K = scale * ex["K"]
    rng = np.random.default_rng(seed)
    e = rng.multivariate_normal(np.zeros(2), P, n_draws)            # prior errors
    v = rng.normal(0.0, math.sqrt(R[0, 0]), n_draws)                # measurement noise
    e_post = e - (K @ (H @ e.T + v[None, :])).T                     # x+ − truth
    mc = np.cov(e_post.T)
    joseph = joseph_covariance(P, H, R, K)
    simple = (np.eye(2) - K @ H) @ P
    se = np.sqrt((mc**2 + np.outer(np.diag(mc), np.diag(mc))) / (n_draws - 1))   # sd of each entry
    return {"scale": scale, "K": K, "monte_carlo": mc, "joseph": joseph, "simple": simple,
            "mc_se": se, "joseph_z": (joseph - mc) / se, "simple_z": (simple - mc) / se,
            "simple_asymmetry": float(abs(simple[0, 1] - simple[1, 0]))}


# ----------------------------------------------------------------------------- section 4

def same_covariance(n_steps=20, seed=4) -> dict:
    """Section 4: the position-velocity filter run twice on two different measurement
    sequences (the second with every fix moved by a random 0-50 m): the means differ, the
    covariances are the same floating-point numbers."""
    ex = position_velocity_example()
    F, Q, H, R = ex["F"], ex["Q"], ex["H"], ex["R"]
    rng = np.random.default_rng(seed)
    z1 = 5.0 * np.arange(1, n_steps + 1) + rng.normal(0, 2.0, n_steps)
    z2 = z1 + rng.uniform(0, 50, n_steps)
    out = []
    for z in (z1, z2):
        x, P = np.zeros(2), np.diag([4.0, 100.0])
        for zk in z:
            x, P = kalman.kf_predict(x, P, F, Q)
            x, P = kalman.kf_update(x, P, [zk], H, R)
        out.append((x, P))
    (x1, P1), (x2, P2) = out
    return {"x1": x1, "x2": x2, "P1": P1, "P2": P2,
            "mean_difference": float(np.max(np.abs(x1 - x2))),
            "covariance_difference": float(np.max(np.abs(P1 - P2)))}


# ----------------------------------------------------------------------------- section 5

def gate_coverage(p=0.95, n=20_000, seed=5) -> dict:
    """Section 5: innovations drawn from their own S (a right filter), for 1, 2 and 3
    entries: the share inside the gate chi2.ppf(p, m) and its binomial 95 % interval; and
    the share inside a 1-D '3 sigma' rule (d2 <= 9) used with every dimension."""
    rng = np.random.default_rng(seed)
    rows = []
    for m in (1, 2, 3):
        A = rng.normal(size=(m, m))
        S = A @ A.T + 0.1 * np.eye(m)
        nu = rng.multivariate_normal(np.zeros(m), S, n)
        d2 = np.einsum("ij,ij->i", nu, np.linalg.solve(S, nu.T).T)
        t = kalman.innovation_gate(nu[0], S, p)[1]
        share = float(np.mean(d2 <= t))
        half = 1.96 * math.sqrt(p * (1 - p) / n)
        rows.append({"m": m, "threshold": t, "share": share, "band": (p - half, p + half),
                     "share_3sigma": float(np.mean(d2 <= 9.0))})
    return {"p": p, "n": n, "rows": rows}


# ----------------------------------------------------------------------------- section 6

def range_example(x0, var0, z, *, offset=5.0, r=0.01) -> dict:
    """Section 6: a car at unknown position x along a road, ranged from a beacon ``offset``
    metres to the side of x = 0: h(x) = sqrt(x^2 + offset^2), nonlinear. The EKF update
    (H = dh/dx at the prior mean) against the exact posterior on a grid."""
    x0, var0 = _checks.real("x0", x0), _checks.real("var0", var0, lo=0.0, strict=True)

    def h(x):
        return np.sqrt(np.asarray(x) ** 2 + offset**2)

    H = x0 / math.sqrt(x0**2 + offset**2)
    S = H * var0 * H + r
    K = var0 * H / S
    mu_ekf, var_ekf = x0 + K * (z - float(h(x0))), (1 - K * H) * var0
    g = _grid(x0 - 8 * math.sqrt(var0) - 2, x0 + 8 * math.sqrt(var0) + 2, 0.002)
    post = kalman.grid_update(kalman.gaussian_pdf(g, x0, var0), g, z, r, h)
    m = kalman.grid_moments(post, g)
    return {"x0": x0, "var0": var0, "z": z, "offset": offset, "r": r, "H": H,
            "ekf": (mu_ekf, var_ekf), "exact": (m["mean"], m["var"]), "grid": g,
            "density": post, "modes": _modes(g, post)}


def _modes(g, p) -> list[float]:
    """Local maxima holding at least 5 % of the peak density."""
    i = np.flatnonzero((p[1:-1] > p[:-2]) & (p[1:-1] >= p[2:]) & (p[1:-1] > 0.05 * p.max())) + 1
    return [float(g[k]) for k in i]


def linearisation_figure(cases: list[dict]):
    """Exact posterior (grid) against the EKF's Gaussian for each range example."""
    fig, axs = figure(1, len(cases), height=3.4)
    for ax, c in zip(np.atleast_1d(axs), cases):
        g = c["grid"]
        ax.plot(g, kalman.gaussian_pdf(g, c["x0"], c["var0"]), color="0.6", label="prior")
        ax.fill_between(g, c["density"], color=GREEN, alpha=0.35, label="exact posterior")
        m, v = c["ekf"]
        ax.plot(g, kalman.gaussian_pdf(g, m, v), color=RED, lw=1.5, label="EKF posterior")
        sd = math.sqrt(c["var0"])
        ax.set(xlabel="position along the road [m]", xlim=(c["x0"] - 4 * sd - 1, c["x0"] + 4 * sd + 1),
               title=f"prior at {c['x0']:.1f} m: H = {c['H']:.2f}")
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axs)[0].set_ylabel("density [1/m]")
    np.atleast_1d(axs)[0].legend(loc="upper left")
    return fig


# ----------------------------------------------------------------------------- section 7

def update_summary(mu=12.0, var=0.34, z=12.4, r=0.16) -> dict:
    """What the explorer shows for one setting: gain, posterior, and how far the posterior
    moved towards the measurement."""
    m, v, K = kalman.update_1d(mu, var, z, r)
    return {"mu": mu, "var": var, "z": z, "r": r, "K": K, "mu_post": m, "var_post": v,
            "sd_post": math.sqrt(v)}


def draw_update(s: dict, ax) -> None:
    lo = min(s["mu"] - 4 * math.sqrt(s["var"]), s["z"] - 4 * math.sqrt(max(s["r"], 1e-6)))
    hi = max(s["mu"] + 4 * math.sqrt(s["var"]), s["z"] + 4 * math.sqrt(max(s["r"], 1e-6)))
    g = np.linspace(lo, hi, 400)
    for m, v, color, label in [(s["mu"], s["var"], BLUE, "prior"),
                               (s["z"], s["r"], ORANGE, "measurement"),
                               (s["mu_post"], s["var_post"], GREEN, "posterior")]:
        if v > 0:
            ax.plot(g, kalman.gaussian_pdf(g, m, v), color=color, lw=2, label=label)
        else:
            ax.axvline(m, color=color, lw=2, label=f"{label} (exact)")
    ax.set(xlabel="x [m]", ylabel="density", title=f"K = {s['K']:.2f}")
    ax.legend(loc="upper right")
    ax.grid(True, alpha=0.3)


def update_explorer(*, mu=12.0, var=0.34, z=12.4, r=0.16):
    """Sliders for the prior variance, the measurement and its variance; shows the three
    densities and the gain. ``widget.holder['summary']`` keeps the latest
    :func:`update_summary`."""
    holder = {}

    def draw(prior_var: float, measurement: float, measurement_var: float) -> None:
        try:
            s = update_summary(mu, prior_var, measurement, measurement_var)
        except ValueError as exc:                # both variances 0
            holder["summary"] = {"error": str(exc)}
            print(f"no update: {exc}")
            return
        fig, ax = widget_figure(figsize=UPDATE_FIGSIZE)
        draw_update(s, ax)
        holder["summary"] = s
        print(f"K = {s['K']:.3f}: posterior {s['mu_post']:.3f} m, σ {s['sd_post']:.3f} m "
              f"(prior σ {math.sqrt(prior_var):.3f} m, measurement σ {math.sqrt(measurement_var):.3f} m)")
        show_widget_figure(fig)

    slider = dict(continuous_update=False, readout_format=".2f")
    widget = interactive(
        draw,
        prior_var=FloatSlider(value=var, min=0.0, max=2.0, step=0.02,
                              description="prior var", **slider),
        measurement=FloatSlider(value=z, min=mu - 3.0, max=mu + 3.0, step=0.1,
                                description="z", **slider),
        measurement_var=FloatSlider(value=r, min=0.0, max=2.0, step=0.02,
                                    description="meas. var", **slider))
    widget.holder = holder
    return keyboard_ready(widget)
