"""mcit's deterministic renderer of scenes (shaded bodies seen through C, sensor noise) and the
prerecorded video made with it. See docs/scenes.md."""

from .raycast import BodyCaster, Hits, SceneCaster
from .renderer import Renderer, lattice_offsets, render_frame, value_noise

__all__ = ["BodyCaster", "Hits", "SceneCaster", "Renderer", "render_frame", "lattice_offsets", "value_noise"]
