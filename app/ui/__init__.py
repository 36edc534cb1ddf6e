"""The operator interface on viser: the video with the database overlaid, and the workflows.

``InterfaceServer(site, grabber, host=..., port=...)`` serves it; ``mcit serve`` builds one
(app/ui/serve.py). Names load lazily so that ``mcit --help`` does not import viser.
"""

from __future__ import annotations

__all__ = ["InterfaceServer"]


def __getattr__(name: str):
    if name == "InterfaceServer":
        from .server import InterfaceServer

        return InterfaceServer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
