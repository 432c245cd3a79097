"""Every figure the course shows carries alt text (annslam_lib.plots.alt): in the stored
notebooks (cell outputs and the widgets' saved pictures), in a live kernel's display, and in
the widgets' pictures."""
from __future__ import annotations

import base64
import json
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from annslam_lib.plots import alt, style  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9]*.ipynb"))


def _pictures(nb: dict):
    """(where, output) for every PNG output: the cells' and those kept in saved widget state."""
    for k, cell in enumerate(nb["cells"]):
        for o in cell.get("outputs", []):
            if "image/png" in o.get("data", {}):
                yield f"cell {k}", o
    for model_id, model in nb["metadata"].get("widgets", {}).get(
            "application/vnd.jupyter.widget-state+json", {}).get("state", {}).items():
        for o in model.get("state", {}).get("outputs", []) or []:
            if "image/png" in o.get("data", {}):
                yield f"widget {model_id[:8]}", o


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_stored_figure_has_alt_text(path):
    nb = json.loads(path.read_text())
    found = list(_pictures(nb))
    assert found, f"{path.name} stores no figure"
    missing = [w for w, o in found
               if len(o.get("metadata", {}).get("image/png", {}).get("alt", "")) < alt.MIN_LENGTH]
    assert not missing, (f"{path.name}: {len(missing)} of {len(found)} figures without alt text "
                         f"({', '.join(missing)}); refresh the notebook (./course.sh refresh)")


def test_the_alt_text_reads_the_figure():
    fig, axs = plt.subplots(1, 2)
    axs[0].plot([1, 2], label="standard EKF")
    axs[0].plot([2, 1], label=r"$\sigma_r$ bound")
    axs[0].set(xlabel="time [s]", ylabel="NEES", yscale="log", title="pose")
    axs[0].legend()
    axs[1].imshow(np.eye(3))
    axs[1].set(xlabel="column", ylabel="row", title="correlation")
    fig.suptitle("two filters")
    text = alt.alt_text(alt.describe(fig, "The EKF's NEES climbs above its bound"))
    assert text == ("The EKF's NEES climbs above its bound. Figure of 2 panels \"two filters\". "
                    "Panel 1, \"pose\": NEES (log scale) against time [s]; showing standard EKF, "
                    "sigma_r bound. Panel 2, \"correlation\": an image over row and column.")
    plt.close(fig)


def test_shared_axes_and_small_multiples_are_read_as_a_reader_would():
    fig, axs = plt.subplots(2, 1, sharex=True)
    axs[0].plot([1, 2])
    axs[0].set(ylabel="speed [m/s]", title="what the car logged")
    axs[1].plot([2, 1])
    axs[1].set(ylabel="steering [deg]", xlabel="time [s]")
    assert alt.alt_text(fig) == ('Figure of 2 panels. Panel 1, "what the car logged": speed [m/s] '
                                 "against time [s]. Panel 2, steering [deg] against time [s].")
    many, axs = plt.subplots(1, 3)
    for ax, d in zip(axs, (1, 2, 5)):
        ax.plot([0, d], label="truth")
        ax.set(xlabel="x [m]", ylabel="y [m]", title=f"at {d} m")
        ax.legend()
    assert alt.alt_text(many) == ('Figure of 3 panels, each y [m] against x [m]; showing truth, '
                                  'titled "at 1 m", "at 2 m", "at 5 m".')
    plt.close(fig)
    plt.close(many)


def test_a_colour_bar_is_not_a_panel_and_a_bare_figure_says_little():
    fig, ax = plt.subplots()
    im = ax.imshow(np.eye(2))
    fig.colorbar(im, label="weight")
    ax.set(xlabel="x [m]", ylabel="y [m]")
    assert alt.alt_text(fig) == "Figure: an image over y [m] and x [m]."
    fig2, _ = plt.subplots()
    assert len(alt.alt_text(fig2)) < alt.MIN_LENGTH        # what the stored-notebook test refuses
    plt.close(fig)
    plt.close(fig2)


def test_bad_input_is_refused():
    with pytest.raises(TypeError, match="matplotlib Figure"):
        alt.alt_text("a plot")
    fig, _ = plt.subplots()
    with pytest.raises(ValueError, match="non-empty"):
        alt.describe(fig, "  ")
    with pytest.raises(ValueError, match="alt text"):
        style.show_png(b"\x89PNG", "a plot")
    plt.close(fig)


def test_outside_ipython_install_does_nothing():
    assert alt.install() is False


def test_a_kernel_shows_figures_with_alt_text_and_the_same_pixels():
    """In a real kernel: notebook_setup makes the inline backend's figures carry alt text,
    also after the backend is configured again, and the PNG is the inline backend's own
    (byte for byte the picture drawn without the alt text)."""
    import nbformat
    from nbclient import NotebookClient
    from nbformat.v4 import new_code_cell, new_notebook

    draw = ("fig, ax = plt.subplots(figsize=(4, 3))\n"
            "ax.plot([0, 1], [1, 3], label='EKF')\nax.legend()\n"
            "ax.set(xlabel='time [s]', ylabel='error [m]', title='drift')\n")
    nb = new_notebook(cells=[
        # the course's style without the alt text first (install switched off), then with it
        new_code_cell("import matplotlib.pyplot as plt\nfrom annslam_lib.plots import alt, style\n"
                      "install, alt.install = alt.install, lambda: False\n"
                      "style.notebook_setup()\n" + draw),
        new_code_cell("alt.install = install\nstyle.notebook_setup()"),
        new_code_cell(draw),
        new_code_cell("%config InlineBackend.figure_formats = ['png']\n" + draw),
    ])
    NotebookClient(nb, timeout=120, kernel_name="python3").execute()
    outs = [[o for o in c.outputs if "image/png" in o.get("data", {})] for c in nb.cells]
    assert [len(o) for o in outs] == [1, 0, 1, 1]
    assert "alt" not in outs[0][0].get("metadata", {}).get("image/png", {})
    expected = 'Figure: "drift": error [m] against time [s]; showing EKF.'
    for o in (outs[2][0], outs[3][0]):
        assert o.metadata["image/png"]["alt"] == expected
    png = [base64.b64decode(o[0]["data"]["image/png"]) for o in outs if o]
    assert png[0] == png[1] == png[2]
    nbformat.validate(nb)


def test_an_html_export_with_the_classic_template_carries_the_alt_text():
    """INSTRUCTOR.md, Accessibility: `jupyter nbconvert --to html --template classic` writes
    each stored figure's alt text as its image's alt attribute, in order."""
    from html.parser import HTMLParser

    import nbformat
    from nbconvert import HTMLExporter

    path = ROOT / "notebooks" / "01a_kalman_filter.ipynb"
    nb = nbformat.read(path, as_version=4)
    body, _ = HTMLExporter(template_name="classic").from_notebook_node(nb)
    shown = []

    class Images(HTMLParser):
        def handle_starttag(self, tag, attrs):
            if tag == "img":
                shown.append(dict(attrs).get("alt"))

    Images().feed(body)
    stored = [o.metadata["image/png"]["alt"] for c in nb.cells if c.cell_type == "code"
              for o in c.outputs if "image/png" in o.get("data", {})]
    assert len(stored) >= 4 and shown == stored
