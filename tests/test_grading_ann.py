"""Checks of notebook 07's graded exercises (annslam_lib.grading.ann): the references are the
library's, the notebook's solutions pass, the paper's printed neuron and the usual slips fail
with their own messages, and the stubs say 'not written yet'."""

import numpy as np
import pytest
import torch

from annslam_lib import ann
from annslam_lib import paper
from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import ann as gk
from solutions import solution
from check_support import stub


# ----------------------------------------------------------------------------- forward pass

notebook_forward = solution("07", "my_forward")


def _forward_with(hidden=np.tanh, norm=True, denorm=True, out=lambda y: y):
    def f(X, W1, b1, W2, b2, x_mean, x_std, y_mean, y_std):
        xt = (X - x_mean) / x_std if norm else X
        y = out(hidden(xt @ W1.T + b1) @ W2.T + b2)
        return y * y_std + y_mean if denorm else y
    return f


@pytest.fixture(scope="module")
def trained():
    """A small network trained by the library on a synthetic set (a learnable range bias)."""
    rng = np.random.default_rng(5)
    n = 120
    pose = np.c_[rng.uniform(-5, 5, (n, 2)), rng.uniform(-3, 3, n)]
    z = np.c_[rng.uniform(2, 25, n), rng.uniform(0.2, 2.9, n)]
    X, base = ann.encode(pose, z)
    target = base + 0.05 * np.c_[np.cos(pose[:, 2]), np.sin(pose[:, 2])]
    ts = ann.TrainingSet(X=X, Y=target - base, base=base, target=target, beacon=np.arange(n) % 6,
                         t=np.arange(n) * 0.1, scan=np.arange(n), pose=pose, z=z)
    model = ann.train(ts, ann.chronological_split(ts), ann.TrainConfig(hidden=(4,), max_epochs=5))
    return model, X


def test_reference_is_the_trained_networks_layout(trained):
    """The flat theta is W1, b1, W2, b2 row by row: the notebook's three lines of NumPy on the
    unpacked weights reproduce TrainedModel.correction."""
    model, X = trained
    th = model.theta.numpy()
    W1, b1 = th[:48].reshape(4, 12), th[48:52]
    W2, b2 = th[52:60].reshape(2, 4), th[60:62]
    args = (X, W1, b1, W2, b2, model.x_mean, model.x_std, model.y_mean, model.y_std)
    np.testing.assert_allclose(notebook_forward(*args), model.correction(X), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(gk.reference_forward(*args), model.correction(X), rtol=1e-12)
    with pytest.raises(ValueError, match="weights must be"):
        gk.reference_forward(X, W1.T, b1, W2, b2, model.x_mean, model.x_std, model.y_mean, model.y_std)


def test_forward_solution_and_reference_pass():
    assert gk.check_forward(notebook_forward, quiet=True).startswith("✓ my_forward agrees")
    for seed in (1, 7):
        gk.check_forward(notebook_forward, seed=seed, n=9, quiet=True)
    gk.check_forward(gk.reference_forward, quiet=True)


@pytest.mark.parametrize("side", [1, 0])
def test_forward_paper_neuron_fails_naming_the_erratum(side):
    """The paper's printed neuron (section 4.2), either printed side, in the hidden layer."""
    def printed(X, W1, b1, W2, b2, x_mean, x_std, y_mean, y_std):
        xt = (X - x_mean) / x_std
        h = paper.ann_neuron_printed(W1, xt[:, None, :], b1)[side]
        return (h @ W2.T + b2) * y_std + y_mean
    with pytest.raises(GradingError, match=r"erratum '4\.2-ann'") as e:
        gk.check_forward(printed)
    assert "printed" in str(e.value) and "back-propagation" in str(e.value)
    assert "tanh" not in str(e.value)             # the transfer function is the exercise's
    with full_feedback(), pytest.raises(GradingError, match=r"erratum '4\.2-ann'.*tanh"):
        gk.check_forward(printed)
    # the plain np.sign student gets the same diagnosis
    with pytest.raises(GradingError, match="4.2-ann"):
        gk.check_forward(_forward_with(hidden=np.sign))


@pytest.mark.parametrize("wrong, phrase", [
    (_forward_with(hidden=lambda s: 1 / (1 + np.exp(-s))), "logistic sigmoid"),
    (_forward_with(out=np.tanh), "output layer is linear"),
    (_forward_with(norm=False), "raw inputs"),
    (_forward_with(denorm=False), "undo the output normalisation"),
    (lambda X, W1, b1, W2, b2, xm, xs, ym, ys: np.tanh((X - xm) / xs @ W1.T) @ W2.T * ys + ym + b2 * ys,
     "bias b1 is missing"),
    (lambda X, W1, b1, W2, b2, xm, xs, ym, ys: notebook_forward(X, W1, b1, W2, b2, xm, xs, ym, ys) + X[:, -2:],
     "corrected LANDMARK"),
    (lambda X, W1, b1, W2, b2, xm, xs, ym, ys: (np.tanh((X - xm) / xs @ W1.T + b1) @ W2.T + b2 - ym) / ys,
     "normalised the output again"),
])
def test_forward_mistakes_have_their_message(wrong, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_forward(wrong)


def test_forward_generic_and_shape_errors():
    def transposed_w2(X, W1, b1, W2, b2, x_mean, x_std, y_mean, y_std):
        return notebook_forward(X, W1, b1, W2, b2, x_mean, x_std, y_mean, y_std)[:, ::-1]
    with pytest.raises(GradingError, match=r"disagrees with the reference at \d+ of 4 inputs"):
        gk.check_forward(transposed_w2)
    with pytest.raises(GradingError, match=r"returned shape \(6,\) .* expected shape \(6, 2\)"):
        gk.check_forward(lambda *a: notebook_forward(*a)[:, 0])
    with pytest.raises(GradingError, match="raised ValueError"):
        gk.check_forward(lambda X, W1, *a: X @ W1)


def test_forward_stub():
    with pytest.raises(GradingError, match="is not written yet"):
        gk.check_forward(stub)


# ----------------------------------------------------------------------------- mapminmax

notebook_mapminmax = solution("07", "my_mapminmax")
notebook_mapminmax_reverse = solution("07", "my_mapminmax_reverse")


def test_mapminmax_reference_is_matlabs_documented_example():
    """MATLAB's documentation example (rows are variables there, columns here):
    x1 = [1 2 4; 1 1 1; 3 2 2; 0 0 0] -> [-1 -1/3 1; 1 1 1; 1 -1 -1; 0 0 0] (constant rows
    unchanged), then the same settings applied to x2 = [5 2 3; ...]."""
    x1 = np.array([[1, 2, 4], [1, 1, 1], [3, 2, 2], [0, 0, 0]], float).T
    lo, hi = x1.min(axis=0), x1.max(axis=0)
    y1 = gk.mapminmax(x1, lo, hi)
    np.testing.assert_allclose(y1.T, [[-1, -1 / 3, 1], [1, 1, 1], [1, -1, -1], [0, 0, 0]], atol=1e-15)
    x2 = np.array([[5, 2, 3], [1, 1, 1], [6, 7, 3], [0, 0, 0]], float).T
    np.testing.assert_allclose(gk.mapminmax(x2, lo, hi)[:, 0], [5 / 3, -1 / 3, 1 / 3], atol=1e-15)
    np.testing.assert_allclose(gk.mapminmax_reverse(y1, lo, hi), x1, atol=1e-14)
    with pytest.raises(ValueError, match="xmin <= xmax"):
        gk.mapminmax(x1, hi, lo)
    with pytest.raises(ValueError, match=r"\(n, F\)"):
        gk.mapminmax(x1[0], lo, hi)


def test_mapminmax_solution_passes():
    assert "invert each other" in gk.check_mapminmax(notebook_mapminmax, notebook_mapminmax_reverse,
                                                     quiet=True)
    gk.check_mapminmax(gk.mapminmax, gk.mapminmax_reverse, seed=8, n=8, quiet=True)

    def in_place(x, xmin, xmax):          # edits its input: the check works on copies
        span = xmax - xmin
        x -= xmin
        x *= 2.0 / np.where(span > 0, span, 1.0)
        x -= 1.0
        xmin *= 1.0
        return np.where(span > 0, x, (x + 1.0) / 2.0 + xmin)
    gk.check_mapminmax(in_place, notebook_mapminmax_reverse, quiet=True)


@pytest.mark.parametrize("kind, phrase", [("unit", r"\[0, 1\]"), ("clip", "clips"),
                                          ("own", "of x itself"), ("const_zero", "constant column"),
                                          ("const_minus_one", "constant column")])
def test_mapminmax_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_mapminmax(gk._mm_wrong(kind), notebook_mapminmax_reverse)


@pytest.mark.parametrize("kind, phrase", [("forward", "forward mapping again"),
                                          ("no_shift", "does not shift back"),
                                          ("no_plus_one", "wrong x at the ends"),
                                          ("unit", r"inverts the \[0, 1\] scaling")])
def test_mapminmax_reverse_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_mapminmax(notebook_mapminmax, gk._mm_reverse_wrong(kind))


def test_mapminmax_division_by_zero_and_stubs():
    def naive(x, xmin, xmax):
        return 2 * (x - xmin) / (xmax - xmin) - 1
    with pytest.raises(GradingError, match="division by zero.*unchanged"):
        gk.check_mapminmax(naive, notebook_mapminmax_reverse)
    with pytest.raises(GradingError, match="stub is not written yet"):
        gk.check_mapminmax(stub, notebook_mapminmax_reverse)
    with pytest.raises(GradingError, match="stub is not written yet"):
        gk.check_mapminmax(notebook_mapminmax, stub)


# ----------------------------------------------------------------------------- training loop

notebook_train_loop = solution("07", "my_train_loop")


def mse_loss_loop(net, X, Y, optimizer, epochs):
    """The same loop written with torch's own loss and zero_grad(set_to_none=False)."""
    out = []
    mse = torch.nn.MSELoss()
    for _ in range(epochs):
        optimizer.zero_grad(set_to_none=False)
        loss = mse(net(X), Y)
        loss.backward()
        optimizer.step()
        out.append(loss)                       # tensors are accepted too
    return out


def test_train_loop_solutions_pass_and_leave_threads_alone():
    threads = torch.get_num_threads()
    assert gk.check_train_loop(notebook_train_loop, quiet=True).startswith("✓ my_train_loop")
    gk.check_train_loop(mse_loss_loop, seed=3, quiet=True)
    gk.check_train_loop(gk.reference_train_loop, quiet=True)
    assert torch.get_num_threads() == threads


def test_reference_loop_learns_deterministically():
    for case in range(3):
        l1, w1 = gk.run_loop(gk.reference_train_loop, case)
        l2, w2 = gk.run_loop(gk.reference_train_loop, case)
        np.testing.assert_array_equal(l1, l2)
        np.testing.assert_array_equal(w1, w2)
        assert l1[-1] < 0.6 * l1[0]          # the toy problem is learnable in 30 epochs


@pytest.mark.parametrize("label", list(gk.LOOP_MISTAKES))
def test_each_known_loop_mistake_gets_its_message(label):
    message, wrong = gk.LOOP_MISTAKES[label]
    with pytest.raises(GradingError) as e:
        gk.check_train_loop(wrong)
    assert message in str(e.value)


def test_loop_mistake_messages_name_the_cause():
    msgs = {k: m for k, (m, _) in gk.LOOP_MISTAKES.items()}
    assert "accumulate" in msgs["no zero_grad"] and "missing" in msgs["no zero_grad"]
    assert "does not decrease" in msgs["no step"] and "SUM" in msgs["sum instead of mean"]
    # which call is missing, and the order, is what exercise 7.2 asks: not in the messages
    assert not any("zero_grad()" in m or ".mean()" in m for m in msgs.values())
    assert set(gk.LOOP_ANSWERS) <= set(gk.LOOP_MISTAKES)


def test_loop_answers_are_in_the_instructors_feedback_only():
    from grading_support import both_feedbacks

    message, wrong = gk.LOOP_MISTAKES["no zero_grad"]
    plain, full = both_feedbacks(gk.check_train_loop, wrong)
    assert "zero_grad()" not in plain
    assert "optimizer.zero_grad() at the start of every epoch" in full


def test_mapminmax_formula_is_in_the_instructors_feedback_only():
    formula = "x = (y + 1) (xmax - xmin) / 2 + xmin"
    with pytest.raises(GradingError) as plain:
        gk.check_mapminmax(notebook_mapminmax, gk._mm_reverse_wrong("no_shift"))
    assert formula not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError, match=r"\(y \+ 1\)"):
        gk.check_mapminmax(notebook_mapminmax, gk._mm_reverse_wrong("no_shift"))


def test_train_loop_other_mistakes():
    def ascent(net, X, Y, optimizer, epochs):
        losses = []
        for _ in range(epochs):
            optimizer.zero_grad()
            loss = ((net(X) - Y) ** 2).mean()
            (-loss).backward()
            optimizer.step()
            losses.append(loss.item())
        return losses
    with pytest.raises(GradingError, match="the loss does not decrease"):
        gk.check_train_loop(ascent)

    def own_optimizer(net, X, Y, optimizer, epochs):
        return notebook_train_loop(net, X, Y, torch.optim.SGD(net.parameters(), lr=0.05), epochs)
    with pytest.raises(GradingError, match="first loss agrees, so the loss is right but the update"):
        gk.check_train_loop(own_optimizer)

    def no_return(net, X, Y, optimizer, epochs):
        notebook_train_loop(net, X, Y, optimizer, epochs)
    with pytest.raises(GradingError, match="forget `return losses`"):
        gk.check_train_loop(no_return)

    def one_short(net, X, Y, optimizer, epochs):
        return notebook_train_loop(net, X, Y, optimizer, epochs - 1)
    with pytest.raises(GradingError, match="returned 29 losses for 30 epochs"):
        gk.check_train_loop(one_short)

    def no_grad(net, X, Y, optimizer, epochs):
        with torch.no_grad():
            return notebook_train_loop(net, X, Y, optimizer, epochs)
    with pytest.raises(GradingError, match="raised RuntimeError"):
        gk.check_train_loop(no_grad)


def test_train_loop_stub():
    with pytest.raises(GradingError, match="stub is not written yet"):
        gk.check_train_loop(stub)
