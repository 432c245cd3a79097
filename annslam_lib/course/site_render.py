"""The site's notebook renderer (myst-nb's ``nb_render_plugin = "annslam"``, registered in
``pyproject.toml``): myst-nb's own, except that a picture's ``alt`` attribute is the alt text
its output's metadata carries (``{"image/png": {"alt": ...}}``, written by
``plots.alt``), which myst-nb itself does not read."""
from __future__ import annotations

from myst_nb.core.render import MimeData, NbElementRenderer

__all__ = ["AltTextRenderer"]


class AltTextRenderer(NbElementRenderer):
    """myst-nb's renderer, with each picture's alt text from its output's metadata."""

    def render_image(self, data: MimeData):
        nodes = super().render_image(data)
        alt = data.output_metadata.get(data.mime_type, {}).get("alt")
        if isinstance(alt, str) and alt.strip():
            for node in nodes:
                node["alt"] = alt
        return nodes
