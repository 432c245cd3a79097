"""The paper's printed equations (annslam_lib.paper): each erratum is numerically
wrong as printed and right as corrected; each confirmed equation is right."""
import numpy as np
import pytest

from annslam_lib import paper
from annslam_lib.models.geometry import wrap_angle
from annslam_lib.models.vehicle import Vehicle
from annslam_lib.models import motion
from annslam_lib.models import observation

TOY = Vehicle(L=2.0, H=1.0, a=3.0, b=1.0)
NUMERIC = [e for e in paper.ERRATA if e.check is not None]


def test_records_are_complete():
    keys = [e.key for e in paper.ERRATA + paper.CONFIRMED]
    assert len(keys) == len(set(keys))
    for e in paper.ERRATA + paper.CONFIRMED:
        assert e.section.split(",")[0] in {"2.2", "3.3", "4.1", "4.2"}
        assert e.printed and e.correct and e.how_proven and e.quantity
    for e in paper.ERRATA:
        assert e.kind in {"wrong equation", "notation", "ambiguous"}
        # numerical rows carry their check; a notation row may carry one to show what its
        # literal reading would do (2.2-rate), and then says so in its note
        assert e.check is not None or e.kind == "notation", e.key
        if e.kind == "notation" and e.check is not None:
            assert "literal" in e.note and e.check() > 1e-3 and e.check_correct() < 1e-6, e.key
        if e.kind == "ambiguous":
            assert e.note
    assert {e.section.split(",")[0] for e in NUMERIC} == {"2.2", "3.3", "4.1", "4.2"}


@pytest.mark.parametrize("entry", NUMERIC, ids=[e.key for e in NUMERIC])
def test_printed_form_fails_corrected_form_passes(entry):
    assert entry.check() > 1e-3
    if entry.check_correct is not None:
        assert entry.check_correct() < 1e-6


@pytest.mark.parametrize("entry", paper.CONFIRMED, ids=[e.key for e in paper.CONFIRMED])
def test_confirmed_equations_hold(entry):
    assert entry.kind == "correct"
    assert entry.check() < 1e-6


def test_errata_table_rows():
    rows = paper.errata_table()
    assert len(rows) == len(paper.ERRATA)
    for row, e in zip(rows, paper.ERRATA):
        assert row["quantity"] == e.quantity
        assert (row["printed_error"] is None) == (e.check is None)


# ------------------------------------------ printed forms, worked by hand

def test_full_state_printed_by_hand():
    # phi = 0, v = 2, tan(alpha) = 0.5, L = 2, a = 3, b = 1:
    # printed: x = 2 - 1 (3 + 1) 0.5 = 0, y = 0 - 1 (3 - 0) 0.5 = -1.5, phi = 0.5
    # correct: x = 2 - 0.5 (0 + 1) = 1.5, y = 0 + 0.5 (3 - 0) = 1.5
    pose, u = [0.0, 0.0, 0.0], [2.0, np.arctan(0.5)]
    np.testing.assert_allclose(paper.full_state_printed(pose, u, TOY), [0.0, -1.5, 0.5], atol=1e-15)
    np.testing.assert_allclose(motion.laser_velocity(pose, u, TOY), [1.5, 1.5, 0.5], atol=1e-15)


def test_speed_translation_printed_by_hand():
    # tan(alpha) = 0.5, H/L = 0.5: the printed right side is v / 0.75, never v itself
    al = np.arctan(0.5)
    assert paper.speed_translation_printed(1.0, al, TOY) == pytest.approx(4 / 3)
    assert paper.speed_translation_printed(1.0, 0.0, TOY) == pytest.approx(1.0)
    assert motion.axle_speed(0.75, al, TOY)[0] == pytest.approx(1.0)


def test_discrete_heading_row_is_the_rate():
    u = [2.0, np.arctan(0.5)]
    for phi in (-3.0, 0.0, 1.0):
        for inside in (False, True):
            got = paper.discrete_model_printed([1.0, 2.0, phi], u, 0.1, TOY, tan_inside=inside)
            assert got[2] == pytest.approx(0.5)       # V/L tan(alpha), whatever phi was
        assert motion.predict([1.0, 2.0, phi], u, 0.1, TOY)[0][2] == \
            pytest.approx(wrap_angle(phi + 0.05))


def test_two_point_printed_cases():
    theta = paper.two_point_theta_printed([[3.0, 1.0], [2.0, 5.0], [1.0, 0.0]],
                                          [[1.0, 1.0], [2.0, 1.0], [3.0, 2.0]])
    assert theta[0] == pytest.approx(0.0)
    assert theta[1] == pytest.approx(-np.pi / 2)      # but the right point is ABOVE: +pi/2
    assert np.isnan(theta[2])                         # X_l > X_r: no printed case applies
    ij = paper.two_point_ij_printed([[2.0, 1.0]], [0.4])
    assert ij[0, 0] == ij[0, 1]
    frame = observation.landmark_from_two_points([2.0, 5.0], [2.0, 1.0])[0]
    assert frame[2] == pytest.approx(np.pi / 2)


def test_printed_bearing_is_off_by_pi_behind_in_x():
    pose = np.array([1.0, -2.0, 0.4])
    ahead = np.array([[6.0, 3.0], [4.0, -9.0]])       # x_i > x_L
    behind = np.array([[-6.0, 3.0], [-2.0, -9.0]])    # x_i < x_L
    for lm, offset in ((ahead, 0.0), (behind, np.pi)):
        printed = paper.observation_printed(pose, lm)
        z = observation.observe(pose, lm)[0]
        np.testing.assert_allclose(printed[:, 0], z[:, 0])
        np.testing.assert_allclose(np.abs(wrap_angle(printed[:, 1] - z[:, 1])), offset, atol=1e-12)


def test_printed_jacobian_differs_only_in_the_errata_columns():
    rng = np.random.default_rng(9)
    pose = np.c_[rng.uniform(-9, 9, (50, 2)), rng.uniform(-np.pi, np.pi, 50)]
    lm = pose[:, :2] + rng.uniform(2, 20, (50, 2)) * rng.choice([-1, 1], (50, 2))
    _, Hp, Hl = observation.observe(pose, lm)
    H = np.concatenate([Hp, Hl], -1)
    P = paper.observation_jacobian_printed(pose, lm)
    wrong = np.zeros((2, 5), bool)
    wrong[0, 3:] = wrong[1, 4] = True
    np.testing.assert_allclose(P[:, ~wrong], H[:, ~wrong], atol=1e-12)
    assert np.all(np.max(np.abs(P - H)[:, wrong], axis=0) > 1e-3)


def test_ann_printed_sides_by_hand():
    lhs, rhs = paper.ann_neuron_printed([1.0], [1.0], 0.5)
    assert (lhs, rhs) == (1.5, 1.0)
    lhs, rhs = paper.ann_neuron_printed([1.0], [1.0], -2.0)
    assert lhs == rhs == -1.0                         # they agree only by accident


def test_errata_markdown_below_layout_by_key():
    keys = [e.key for e in paper.ERRATA[:2]]
    md = paper.errata_markdown(keys, formulas="below")
    table, _, listing = md.partition("\n\n")
    rows = table.splitlines()
    assert rows[0].count("|") == 7 and len(rows) == 2 + len(keys)    # 6 narrow columns
    items = listing.splitlines()
    assert [line.split("`")[1] for line in items] == keys             # formulas listed below, in order
    for e, line in zip(paper.ERRATA[:2], items):
        assert f"printed ${e.printed}$" in line and f"correct ${e.correct}$" in line
    assert md == paper.errata_markdown(list(paper.ERRATA[:2]), formulas="below")  # records work too
    # the default: every erratum, one table with the formulas inline (docs/errata.md's)
    assert paper.errata_markdown().count("\n") == len(paper.ERRATA) + 1
    with pytest.raises(ValueError, match="formulas"):
        paper.errata_markdown(keys, formulas="beside")
    with pytest.raises((KeyError, ValueError), match="no-such-erratum"):
        paper.errata_markdown(["no-such-erratum"])


def test_a_collapsed_errata_table_is_the_same_table_in_a_closed_box():
    keys = ["4.1-Pl-vector", "4.1-full-x", "4.1-full-y", "4.1-Pl-scalar", "4.1-full-phi"]
    table = paper.errata_markdown(keys, formulas="below")
    boxed = paper.errata_markdown(keys, formulas="below", collapsed=True)
    assert boxed.startswith("<details>\n<summary>") and boxed.endswith("</details>")
    assert "<details open" not in boxed and f"\n\n{table}\n\n" in boxed
    kinds = [r["kind"] for r in paper.errata_table(keys)]
    wrong, right = sum(k != "correct" for k in kinds), kinds.count("correct")
    assert (wrong, right) == (3, 2)
    assert f"{wrong} misprints, {right} confirmed" in boxed
