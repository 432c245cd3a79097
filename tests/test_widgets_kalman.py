"""Chapter 01a explorer, headless: what it shows for a slider setting against the posterior
written independently (precision-weighted average), and its edge cases."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from annslam_lib.chapters import ch01a_kalman_filter as ch  # noqa: E402
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures, move  # noqa: F401


@pytest.mark.parametrize("prior_var, z, meas_var", [(0.34, 12.4, 0.16), (2.0, 9.0, 0.02),
                                                    (0.02, 15.0, 2.0), (1.0, 12.0, 1.0)])
def test_the_explorer_shows_the_precision_weighted_posterior(prior_var, z, meas_var):
    w = ch.update_explorer(mu=12.0, var=0.34, z=12.4, r=0.16)
    s = move(w, **{"prior var": prior_var, "z": z, "meas. var": meas_var})
    info = 1 / prior_var + 1 / meas_var
    assert s["var_post"] == pytest.approx(1 / info, rel=1e-12)
    assert s["mu_post"] == pytest.approx((12.0 / prior_var + z / meas_var) / info, rel=1e-12)
    assert min(12.0, z) <= s["mu_post"] <= max(12.0, z)
    assert s["var_post"] < min(prior_var, meas_var)


def test_an_exact_measurement_moves_the_posterior_onto_it_and_two_exact_ones_say_why_not(capsys):
    w = ch.update_explorer()
    s = move(w, **{"meas. var": 0.0})
    assert (s["mu_post"], s["var_post"], s["K"]) == (pytest.approx(12.4), 0.0, 1.0)
    s = move(w, **{"prior var": 0.0})
    assert "var + r = 0" in s["error"]
    assert "no update" in capsys.readouterr().out


def test_the_figure_draws_the_three_densities():
    s = ch.update_summary(12.0, 0.34, 12.4, 0.16)
    fig, ax = plt.subplots()
    ch.draw_update(s, ax)
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == ["prior", "measurement", "posterior"]
    peak = ax.get_lines()[2].get_xydata()
    assert peak[np.argmax(peak[:, 1]), 0] == pytest.approx(s["mu_post"], abs=0.03)


def test_kept_layout_stays_clear_at_the_controls_ends():
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch.update_explorer(mu=12.0, var=0.34, z=12.4, r=0.16))
