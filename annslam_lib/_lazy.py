"""Lazy subpackage faces (as scikit-image's ``lazy_loader``): ``annslam_lib.data.load``
imports ``annslam_lib.data.loaders`` only when first used, so importing a layer costs
nothing until something in it is needed."""
from __future__ import annotations

import importlib


def attach(package: str, submodules=(), attrs: dict[str, str] | None = None):
    """(__getattr__, __dir__, __all__) for ``package``: ``submodules`` are importable as
    attributes; ``attrs`` maps a public name to the submodule that defines it."""
    attrs = dict(attrs or {})
    names = sorted(set(submodules) | set(attrs))

    def __getattr__(name: str):
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")
        if name in attrs:
            return getattr(importlib.import_module(f"{package}.{attrs[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return names

    return __getattr__, __dir__, names
