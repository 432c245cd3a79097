"""Checks for the graded exercises of notebook 07 "The landmark network" (paper section 4.2).

- :func:`check_forward`: the network's forward pass as nntool's ``fitnet`` builds it, tansig
  (tanh) hidden layer and linear output, with the library's normalisation (inputs and
  outputs standardised by the training part's mean and standard deviation), against
  ``ann.TrainedModel.correction``. The paper's printed neuron (``paper.ann_neuron_printed``,
  erratum ``4.2-ann``) fails with a message naming the erratum.
- :func:`check_train_loop`: the PyTorch training loop (zero_grad / forward / loss / backward /
  step) run side by side with :func:`reference_train_loop` on small fixed problems
  (:func:`toy_problem`), on one thread (the same numbers every run); recognises accumulating gradients, a
  loss that does not decrease, the sum instead of the mean, and other slips
  (:data:`LOOP_MISTAKES`).
- :func:`check_mapminmax`: nntool's default normalisation ``mapminmax`` to [-1, 1] and its
  inverse (:func:`mapminmax`, :func:`mapminmax_reverse`).
"""
from __future__ import annotations

import contextlib
import math
from typing import Callable

import numpy as np

from .. import ann, paper
from ..ann.network import forward as reference_forward
from ..ann.network import mapminmax, mapminmax_reverse
from ..ann.network import one_torch_thread as _one_thread
from ..ann.network import train_loop as reference_train_loop
from .core import (allowing_library_calls, forbids, Passed, GradingError, Mistake, call, check_function,
                   copying, fmt)

__all__ = ["reference_forward", "check_forward", "mapminmax", "mapminmax_reverse",
           "check_mapminmax", "toy_problem", "reference_train_loop", "LOOP_MISTAKES", "LOOP_ANSWERS",
           "run_loop", "check_train_loop"]

_ERRATUM = next(e for e in paper.ERRATA if e.key == "4.2-ann")


# ----------------------------------------------------------------------------- forward pass


def _forward_cases(seed: int, n: int) -> list[dict]:
    """Seeded networks and inputs: realistic features (``ann.encode`` of laser poses and
    measurements 1..30 m away), the normalisation of a larger 'training' sample, weights
    large enough that the tanh is far from linear."""
    rng = np.random.default_rng(seed)

    def features(m):
        pose = np.c_[rng.uniform(-20, 20, (m, 2)), rng.uniform(-np.pi, np.pi, m)]
        z = np.c_[rng.uniform(1, 30, m), rng.uniform(0, np.pi, m)]
        return ann.encode(pose, z, rng.integers(0, 5, m).astype(float), rng.uniform(0, 0.3, m))[0]

    cases = []
    for k, h in enumerate((10, 3, 10, 1)):
        train = features(200)
        F = train.shape[1]
        cases.append(dict(
            label=f"network {k + 1}: {h} hidden unit{'s' if h > 1 else ''}, {n} samples",
            X=features(n), W1=rng.normal(0, 1.5 / math.sqrt(F), (h, F)), b1=rng.normal(0, 0.5, h),
            W2=rng.normal(0, 1.0, (2, h)), b2=rng.normal(0, 0.3, 2),
            x_mean=train.mean(axis=0), x_std=train.std(axis=0),
            y_mean=rng.normal(0, 0.05, 2), y_std=rng.uniform(0.05, 0.3, 2)))
    return cases


_FORWARD_ARGS = ("X", "W1", "b1", "W2", "b2", "x_mean", "x_std", "y_mean", "y_std")


def _variant(c: dict, *, hidden=np.tanh, out=None, norm="std", denorm="std", bias1=True,
             bias2=True, landmark=False) -> np.ndarray:
    """A (possibly wrong) forward pass on case ``c``, for the known mistakes."""
    X = c["X"]
    xn = {"std": (X - c["x_mean"]) / c["x_std"], "none": X,
          "times": (X - c["x_mean"]) * c["x_std"]}[norm]
    s = xn @ c["W1"].T
    h = hidden(s, c["b1"]) if hidden in _SIGN_FORMS else hidden(s + (c["b1"] if bias1 else 0.0))
    y = h @ c["W2"].T + (c["b2"] if bias2 else 0.0)
    if out is not None:
        y = out(y)
    y = {"std": y * c["y_std"] + c["y_mean"], "none": y,
         "inverse": (y - c["y_mean"]) / c["y_std"], "no_mean": y * c["y_std"]}[denorm]
    if landmark:
        y = y + X[:, -2:]
    return y


def _sign_right(s, b):
    """The printed right-hand side, sign(b + sum w_i x_i), per hidden unit."""
    return paper.ann_neuron_printed(np.ones(1), s[..., None], b)[1]


def _sign_left(s, b):
    """The printed left-hand side, sign(<w, x>) + b."""
    return paper.ann_neuron_printed(np.ones(1), s[..., None], b)[0]


_SIGN_FORMS = (_sign_right, _sign_left)


def _logsig(s):
    return 1.0 / (1.0 + np.exp(-s))


_ERRATUM_TEXT = (f"(paper section {_ERRATUM.section}, erratum {_ERRATUM.key!r} in "
                 f"annslam_lib.paper.ERRATA: printed ${_ERRATUM.printed}$)")


def _forward_mistakes(cases: list[dict]) -> list[Mistake]:
    lut = {c["label"]: c for c in cases}

    def m(message, answer="", **kw):
        return Mistake(message, lambda label, kw=kw: _variant(lut[label], **kw), answer)

    return [
        m("your hidden layer is the paper's printed neuron sign(b + Σ w_i x_i) " + _ERRATUM_TEXT
          + ". A sign unit outputs only -1, 0 or +1 and its derivative is zero everywhere, so "
          "back-propagation cannot train it (section 1). fitnet's hidden transfer function is "
          "named in section 1.", "nntool's fitnet uses tansig = tanh: "
          "h = np.tanh(x~ @ W1.T + b1).", hidden=_sign_right),
        m("your hidden layer is the paper's printed left-hand side sign(<w, x>) + b " + _ERRATUM_TEXT
          + ", which is not even the same function as the printed right-hand side (b outside "
          "the sign). Neither can be trained by back-propagation (zero gradient); fitnet's "
          "hidden transfer function is named in section 1.",
          "Use tansig = tanh: h = np.tanh(x~ @ W1.T + b1).", hidden=_sign_left),
        m("your hidden layer uses the logistic sigmoid 1 / (1 + exp(-s)) (MATLAB's logsig), "
          "not fitnet's hidden transfer function (section 1).",
          "fitnet's hidden layer is tansig, i.e. np.tanh.", hidden=_logsig),
        m("your output layer applies tanh too; fitnet's output layer is linear (purelin), so "
          "that it can output any correction.", "y~ = W2 h + b2.", out=np.tanh),
        m("you fed the raw inputs to the network: normalise them first with the training "
          "statistics.", "x~ = (X - x_mean) / x_std.", norm="none"),
        m("your normalisation multiplies by the standard deviation; it should make every "
          "column of unit spread.", "x~ = (X - x_mean) / x_std.", norm="times"),
        m("you returned the network's normalised output y~; undo the output normalisation "
          "(the correction is in metres).", "y = y~ * y_std + y_mean.", denorm="none"),
        m("you normalised the output again instead of undoing it.",
          "y = y~ * y_std + y_mean, not (y~ - y_mean) / y_std.", denorm="inverse"),
        m("undoing the output normalisation, you forgot the mean.",
          "y = y~ * y_std + y_mean.", denorm="no_mean"),
        m("the hidden layer's bias b1 is missing.", "h = tanh(x~ @ W1.T + b1).", bias1=False),
        m("the output layer's bias b2 is missing.", "y~ = h @ W2.T + b2.", bias2=False),
        m("you returned the corrected LANDMARK (lm_x, lm_y plus the correction), which is what "
          "TrainedModel.predict returns; the network itself outputs the correction only.",
          landmark=True),
    ]


@forbids(reference_forward)
def check_forward(fn: Callable, *, seed: int = 0, n: int = 6, quiet: bool = False) -> str:
    """Exercise 7.1 (notebook 07, section 1): ``fn(X, W1, b1, W2, b2, x_mean, x_std, y_mean,
    y_std)`` must return the correction (n, 2) of :func:`reference_forward` (nntool's fitnet:
    tansig hidden layer, linear output; inputs and outputs standardised) on seeded networks
    of 10, 3 and 1 hidden units. The paper's printed sign neuron fails naming erratum 4.2-ann."""
    cases = _forward_cases(seed, n)
    lut = {c["label"]: c for c in cases}

    def student(label):
        c = lut[label]
        return fn(*(np.array(c[k], copy=True) for k in _FORWARD_ARGS))

    def reference(label):
        c = lut[label]
        return reference_forward(*(c[k] for k in _FORWARD_ARGS))

    student.__name__ = getattr(fn, "__name__", "my_forward")
    return check_function(student, reference, [(c["label"],) for c in cases],
                          name=student.__name__, arg_names=["case"],
                          mistakes=_forward_mistakes(cases),
                          what="the library's network (ann.TrainedModel.correction)",
                          quiet=quiet)


# ----------------------------------------------------------------------------- mapminmax


def _minmax_cases(seed: int, n: int) -> list[tuple]:
    """Bounds from a 'training' sample; inputs partly outside them (test data); the last
    column of the third case constant (xmin = xmax)."""
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(3):
        F = 3
        train = np.c_[rng.uniform(-20, 20, (30, 1)), rng.uniform(1, 30, (30, 1)),
                      rng.uniform(0, np.pi, (30, 1))]
        if k == 2:
            train[:, 2] = 1.0
        xmin, xmax = train.min(axis=0), train.max(axis=0)
        span = np.where(xmax > xmin, xmax - xmin, 1.0)
        x = xmin + span * rng.uniform(-0.3, 1.3, (n, F))   # some outside the training range
        if k == 2:
            x[:, 2] = rng.choice([1.0, 0.0, 2.5], n)
        cases.append((x, xmin, xmax))
    return cases


def _as_settings(x, xmin, xmax):
    return (np.asarray(x, dtype=float), np.asarray(xmin, dtype=float),
            np.asarray(xmax, dtype=float))


def _mm_wrong(kind: str):
    def f(x, xmin, xmax):
        x, xmin, xmax = _as_settings(x, xmin, xmax)
        span = xmax - xmin
        safe = np.where(span == 0, 1.0, span)
        if kind == "unit":
            y = (x - xmin) / safe
        elif kind == "clip":
            y = np.clip(2.0 * (x - xmin) / safe - 1.0, -1.0, 1.0)
        elif kind == "own":
            lo, hi = x.min(axis=0), x.max(axis=0)
            y = 2.0 * (x - lo) / np.where(hi > lo, hi - lo, 1.0) - 1.0
            return np.where(hi > lo, y, x)
        elif kind == "const_zero":
            return np.where(span == 0, 0.0, 2.0 * (x - xmin) / safe - 1.0)
        elif kind == "const_minus_one":
            return np.where(span == 0, -1.0, 2.0 * (x - xmin) / safe - 1.0)
        return np.where(span == 0, x, y)
    return f


def _mm_reverse_wrong(kind: str):
    def f(y, xmin, xmax):
        y, xmin, xmax = _as_settings(y, xmin, xmax)
        span = xmax - xmin
        if kind == "forward":
            return mapminmax(y, xmin, xmax)
        if kind == "no_shift":
            x = (y + 1.0) * span / 2.0
        elif kind == "no_plus_one":
            x = y * span / 2.0 + xmin
        else:  # "unit": the inverse of the [0, 1] scaling
            x = y * span + xmin
        return np.where(span == 0, y, x)
    return f


@forbids(mapminmax, mapminmax_reverse)
def check_mapminmax(fn: Callable, fn_reverse: Callable, *, seed: int = 0, n: int = 5,
                    quiet: bool = False) -> str:
    """Exercise 7.3 (notebook 07, section 3): ``fn(x, xmin, xmax)`` is nntool's mapminmax
    with the training bounds (:func:`mapminmax`), ``fn_reverse(y, xmin, xmax)`` its inverse
    (:func:`mapminmax_reverse`), on inputs partly outside the bounds and a constant column."""
    cases = _minmax_cases(seed, n)
    names = ["x", "xmin", "xmax"]
    name = getattr(fn, "__name__", "my_mapminmax")
    rname = getattr(fn_reverse, "__name__", "my_mapminmax_reverse")
    fn, fn_reverse = copying(fn), copying(fn_reverse)
    for x, lo, hi in cases:                 # a constant column first: the usual slip
        const = lo == hi
        if const.any():
            with np.errstate(all="ignore"):
                y = np.asarray(call(fn, (x, lo, hi), name=name, arg_names=names), dtype=float)
            if y.shape == x.shape and not np.all(np.isfinite(y[:, const])):
                j = int(np.flatnonzero(const)[0])
                raise GradingError(
                    f"{name} returns {fmt(y[0, j])} in column {j}, whose training values are all "
                    f"{fmt(lo[j])} (xmin = xmax): a division by zero. mapminmax leaves a "
                    "constant column unchanged (y = x), as MATLAB documents.")
    check_function(fn, mapminmax, cases, name=name, arg_names=names, quiet=True, mistakes=[
        Mistake(f"{name} maps [xmin, xmax] to [0, 1]; mapminmax maps it to [-1, 1] (the "
                "range where tanh is not flat): check your two conditions.", _mm_wrong("unit"),
                "y = 2 (x - xmin) / (xmax - xmin) - 1."),
        Mistake(f"{name} clips to [-1, 1]. Inputs outside the training range must map outside "
                "[-1, 1]: clipping changes them silently (and hides that the network has to "
                "extrapolate there).", _mm_wrong("clip")),
        Mistake(f"{name} uses the minimum and maximum of x itself; use the training part's "
                "xmin and xmax passed as arguments, the same settings for every later input "
                "(MATLAB: mapminmax('apply', x, PS)).", _mm_wrong("own")),
        Mistake(f"{name} maps a constant column (xmin = xmax) to 0; mapminmax leaves such a "
                "column unchanged, as MATLAB documents.", _mm_wrong("const_zero"), "y = x there."),
        Mistake(f"{name} maps a constant column (xmin = xmax) to -1; mapminmax leaves such a "
                "column unchanged, as MATLAB documents.", _mm_wrong("const_minus_one"),
                "y = x there."),
    ])
    rev_cases = [(mapminmax(x, lo, hi), lo, hi) for x, lo, hi in cases]
    check_function(fn_reverse, mapminmax_reverse, rev_cases, name=rname, quiet=True,
                   arg_names=["y", "xmin", "xmax"], mistakes=[
        Mistake(f"{rname} applies the forward mapping again; it must undo it (solve your "
                "forward map for x).", _mm_reverse_wrong("forward"), "x = (y + 1) (xmax - xmin) / 2 + xmin."),
        Mistake(f"{rname} does not shift back: y = -1 must give xmin.",
                _mm_reverse_wrong("no_shift"), "x = (y + 1) (xmax - xmin) / 2 + xmin."),
        Mistake(f"{rname} gives the wrong x at the ends: y = -1 must give xmin and y = 1 "
                "xmax.", _mm_reverse_wrong("no_plus_one"), "x = (y + 1) (xmax - xmin) / 2 + xmin."),
        Mistake(f"{rname} inverts the [0, 1] scaling; mapminmax's range is [-1, 1].",
                _mm_reverse_wrong("unit"), "x = (y + 1) (xmax - xmin) / 2 + xmin."),
    ])
    # the round trip, on the student's own pair
    for x, lo, hi in cases:
        back = np.asarray(call(fn_reverse, (call(fn, (x, lo, hi), name=name), lo, hi),
                               name=rname), dtype=float)
        if not np.allclose(back, x, rtol=1e-9, atol=1e-9):
            raise GradingError(f"{rname}({name}(x)) does not give x back: at x = {fmt(x[0])} "
                               f"got {fmt(back[0])}.")
    ok = (f"✓ {name} and {rname} agree with nntool's mapminmax on {len(cases)} inputs "
          "(outside the training range and a constant column included) and invert each other.")
    if not quiet:
        print(ok)
    return Passed(ok)


# ----------------------------------------------------------------------------- training loop

def toy_problem(seed: int = 0, n: int = 32, n_in: int = 3, hidden: int = 8):
    """A small fixed regression problem for exercise 7.2: X (n, n_in) in [-1, 1], two smooth
    targets Y (n, 2) plus 0.02 noise, and a fresh fitnet-like network (tanh hidden layer,
    linear output, float64) whose weights are drawn from ``seed`` (the global torch
    generator is not touched). Returns (net, X, Y) as torch objects."""
    import torch

    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (n, n_in))
    Y = np.c_[np.sin(2 * X[:, 0]) + 0.5 * X[:, 1], X[:, 0] * X[:, -1]] + rng.normal(0, 0.02, (n, 2))
    net = torch.nn.Sequential(torch.nn.Linear(n_in, hidden), torch.nn.Tanh(),
                              torch.nn.Linear(hidden, 2)).double()
    with torch.no_grad():
        for layer in (net[0], net[2]):
            s = 1.0 / math.sqrt(layer.in_features)
            for p in (layer.weight, layer.bias):
                p.copy_(torch.from_numpy(rng.uniform(-s, s, tuple(p.shape))))
    return net, torch.from_numpy(X), torch.from_numpy(Y)


#: The optimisers of the check's cases: (label, factory(params), epochs).
_LOOP_CASES = (
    ("SGD, lr 0.1", lambda torch, p: torch.optim.SGD(p, lr=0.1), 30),
    ("SGD with momentum 0.9, lr 0.02", lambda torch, p: torch.optim.SGD(p, lr=0.02, momentum=0.9), 30),
    ("Adam, lr 0.02", lambda torch, p: torch.optim.Adam(p, lr=0.02), 30),
)


def _loop(kind: str):
    """The known wrong loops of :data:`LOOP_MISTAKES`."""
    def f(net, X, Y, optimizer, epochs):
        losses = []
        for _ in range(epochs):
            if kind != "no_zero_grad" and kind != "zero_after_backward":
                optimizer.zero_grad()
            r = net(X) - Y
            loss = {"sum": (r ** 2).sum(), "sum_coords": (r ** 2).sum(dim=1).mean(),
                    "rmse": (r ** 2).mean().sqrt(), "mae": r.abs().mean()}.get(kind, (r ** 2).mean())
            loss.backward()
            if kind == "zero_after_backward":
                optimizer.zero_grad()
            if kind != "no_step":
                optimizer.step()
            if kind == "after_step":
                with _no_grad():
                    loss = ((net(X) - Y) ** 2).mean()
            losses.append(loss.item())
        return losses
    return f


def _no_grad():
    import torch
    return torch.no_grad()


_FROZEN = ("the weights never change, so the loss does not decrease: either the call that "
           "moves the weights is missing, or the gradients are wiped before it can use them. "
           "Look at the order of the pieces.")

#: Known wrong training loops: name -> (message, loop).
LOOP_MISTAKES = {
    "no zero_grad": (
        "the gradients accumulate: every loss.backward() ADDS to .grad, so epoch k steps along "
        "the sum of all gradients so far. One call is missing (section 1 lists the pieces).",
        _loop("no_zero_grad")),
    "zero_grad after backward": (_FROZEN, _loop("zero_after_backward")),
    "no step": (_FROZEN, _loop("no_step")),
    "sum instead of mean": (
        "the loss is the SUM of the squared errors, not nntool's mse (the library's loss). The "
        "sum is n * 2 times larger, and so is its gradient: the same learning rate then means "
        "a much larger step.", _loop("sum")),
    "sum over the two outputs": (
        "the loss sums the squared errors of the two outputs and averages over the samples "
        "only; the mean squared error averages over all 2 n outputs (twice smaller).",
        _loop("sum_coords")),
    "RMSE loss": (
        "the loss is the root of the mean squared error; minimise the MSE itself "
        "(no square root): the gradients differ.", _loop("rmse")),
    "MAE loss": (
        "the loss is the mean ABSOLUTE error; the exercise (and nntool's mse) uses the mean "
        "SQUARED error.", _loop("mae")),
    "loss after the step": (
        "the weights are right but your losses are the ones after each step (one epoch "
        "late); record the loss of the forward pass that the step uses.",
        _loop("after_step")),
}

#: What would hand exercise 7.2 over, per known mistake: shown in the instructor's feedback
#: only (``grading.core.full_feedback``).
LOOP_ANSWERS = {
    "no zero_grad": "Call optimizer.zero_grad() at the start of every epoch.",
    "zero_grad after backward": "The order is zero_grad, forward, loss, backward, step.",
    "no step": "The order is zero_grad, forward, loss, backward, step.",
    "sum instead of mean": "((net(X) - Y) ** 2).mean() or torch.nn.functional.mse_loss.",
    "sum over the two outputs": "((net(X) - Y) ** 2).mean().",
    "loss after the step": "Record loss.item() before optimizer.step().",
}


def _params(net) -> np.ndarray:
    return np.concatenate([p.detach().numpy().ravel().copy() for p in net.parameters()])


def run_loop(loop: Callable, case: int = 0, *, seed: int = 0, name: str = "the loop"):
    """Run ``loop(net, X, Y, optimizer, epochs)`` on case ``case`` of the check (a fresh
    :func:`toy_problem` network from ``seed``, that case's optimiser and epoch count), on one
    thread. Returns (losses as a float array, final weights).
    The student's loop is called through ``grading.core.call``; the check's own loops (the
    reference, which is the very function the exercise forbids, and the known mistakes)
    are exempt from the forbidden-call monitor."""
    import torch

    label, make_opt, epochs = _LOOP_CASES[case]
    net, X, Y = toy_problem(seed)
    opt = make_opt(torch, net.parameters())
    own = loop is reference_train_loop or any(loop is w for _, w in LOOP_MISTAKES.values())
    with _one_thread(), (allowing_library_calls() if own else contextlib.nullcontext()):
        out = call(loop, (net, X, Y, opt, epochs), name=name,
                   arg_names=["net", "X", "Y", "optimizer", "epochs"])
    if out is None:
        raise GradingError(f"{name} returned None ({label}): did you forget `return losses`?")
    try:
        losses = np.array([float(v.detach()) if hasattr(v, "detach") else float(v)
                           for v in out])
    except (TypeError, ValueError):
        raise GradingError(f"{name} returned {type(out).__name__} {out!r:.80}; expected a list "
                           f"of {epochs} loss values (floats), one per epoch") from None
    if losses.size != epochs:
        raise GradingError(f"{name} returned {losses.size} losses for {epochs} epochs ({label}); "
                           "return one loss per epoch, in order.")
    return losses, _params(net)


def _same(a, b) -> bool:
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-7, atol=1e-10, equal_nan=True))


@forbids(reference_train_loop, ann.train)
def check_train_loop(fn: Callable, *, seed: int = 0, quiet: bool = False) -> str:
    """Exercise 7.2 (notebook 07, section 1): ``fn(net, X, Y, optimizer, epochs)`` trains
    ``net`` in place and returns the loss of each epoch (before its step). Run side by side
    with :func:`reference_train_loop` on :func:`toy_problem` (``seed``) with plain SGD, SGD
    with momentum and Adam (30 epochs each, well under a second); the losses and the final
    weights must agree. Known mistakes (:data:`LOOP_MISTAKES`) get their own message."""
    name = getattr(fn, "__name__", "my_train_loop")
    for k, (label, _, epochs) in enumerate(_LOOP_CASES):
        got_l, got_w = run_loop(fn, k, seed=seed, name=name)
        exp_l, exp_w = run_loop(reference_train_loop, k, seed=seed, name="the reference")
        if _same(got_l, exp_l) and _same(got_w, exp_w):
            continue
        where = f" ({label}, {epochs} epochs)"
        for key, (message, wrong) in LOOP_MISTAKES.items():
            wl, ww = run_loop(wrong, k, seed=seed, name="a known mistake")
            if _same(got_l, wl) and _same(got_w, ww):
                told = Mistake(message, wrong, LOOP_ANSWERS.get(key, "")).text
                raise GradingError(f"{name}: {told}{where}")
        w0 = _params(toy_problem(seed)[0])
        if not np.all(np.isfinite(got_l)) or not np.all(np.isfinite(got_w)):
            raise GradingError(f"{name}: the loss or the weights became NaN or infinite{where}; "
                               "the reference's last loss is " f"{exp_l[-1]:.4g}.")
        if _same(got_w, w0):
            raise GradingError(f"{name}: {_FROZEN}{where}")
        if got_l[-1] >= got_l[0]:
            raise GradingError(
                f"{name}: the loss does not decrease{where}: {got_l[0]:.4g} at epoch 0, "
                f"{got_l[-1]:.4g} at the last (the reference goes from {exp_l[0]:.4g} to "
                f"{exp_l[-1]:.4g}). " + Mistake("Minimise the loss, with the optimizer you were "
                                                 "given.", None, "loss.backward() then "
                                                 "optimizer.step().").text)
        if _same(got_l, exp_l):
            raise GradingError(f"{name}: the losses agree with the reference but the final "
                               f"weights do not{where}: one step per epoch, and nothing that "
                               "changes the weights after the loop.")
        e = int(np.argmax(~np.isclose(got_l, exp_l, rtol=1e-7, atol=1e-10)))
        hint = (" " + Mistake("The very first loss differs, so the loss function itself is "
                              "not the mean squared error over all outputs.", None,
                              "((net(X) - Y) ** 2).mean().").text if e == 0 else
                " " + Mistake("The first loss agrees, so the loss is right but the update is "
                              "not.", None, "One zero_grad, backward and step per epoch, with "
                              "the optimizer you were given.").text)
        raise GradingError(f"{name} disagrees with the reference{where}: the loss at epoch {e} "
                           f"is {got_l[e]:.6g}, expected {exp_l[e]:.6g}.{hint}")
    ok = (f"✓ {name} trains like the reference loop (SGD, SGD with momentum, Adam: losses and "
          "final weights agree).")
    if not quiet:
        print(ok)
    return Passed(ok)
