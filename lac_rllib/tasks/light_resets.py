"""Cheap resets of the Safety-Gymnasium navigation tasks: no render-only work on reset.

Every ``reset`` of a navigation env rebuilds its MuJoCo model from XML (a new random layout of
goal, hazards and vases). Measured on one core: 1.2 s per reset, of which 1.1 s was MuJoCo
decoding the six HD PNG images of the star skybox (a 64M-pixel texture, drawn only by a viewer)
and 0.1 s re-parsing ``assets.yaml``, against ~3 ms to compile the same model without them;
with 1000-step episodes that was ~30% of raw env time.

While :func:`light` is active (our wrapper holds it around ``reset`` when the env was made
without a ``render_mode``), the skybox is a 1×1 flat texture and ``assets.yaml`` is parsed once
per process (each build gets a fresh deep copy, as a fresh parse would give). Nothing that the
physics reads changes: bodies, geoms, joints, masses, ``qpos0``, the inverse weights and the
model statistics come out identical, and seeded trajectories are bit-identical to the stock
environment's (tests/tasks/test_light_resets.py). Envs made with a ``render_mode`` keep the stock
path. The layout is still re-placed by safety_gymnasium's own code, so its random stream is
untouched.
"""

from __future__ import annotations

import contextlib
import copy
import threading
from typing import Any, Iterator

#: What replaces the skybox in a light build: one black pixel per face.
TINY_SKYBOX = {"@type": "skybox", "@builtin": "flat", "@width": "1", "@height": "1", "@rgb1": "0 0 0"}

_state = threading.local()


class _AssetsYaml:
    """Stands in for the ``yaml`` module inside ``safety_gymnasium.world`` (only ``load`` and
    ``FullLoader`` are used there): parses each file once, returns deep copies, and swaps the
    skybox while a light build is on."""

    def __init__(self, yaml_module):
        self._yaml = yaml_module
        self.FullLoader = yaml_module.FullLoader
        self._cache: dict[tuple[str, Any], Any] = {}

    def load(self, stream, Loader):  # yaml's own signature (Loader)
        key = (getattr(stream, "name", None), Loader)
        if key[0] is None:
            return self._yaml.load(stream, Loader=Loader)
        if key not in self._cache:
            self._cache[key] = self._yaml.load(stream, Loader=Loader)
        config = copy.deepcopy(self._cache[key])
        if getattr(_state, "light", False) and "skybox" in config.get("textures", {}):
            config["textures"]["skybox"] = dict(TINY_SKYBOX)
        return config

    def __getattr__(self, name: str):
        return getattr(self._yaml, name)


def install() -> None:
    """Put the stand-in into ``safety_gymnasium.world`` (idempotent; after the compat patches)."""
    import safety_gymnasium.world as world

    if not isinstance(world.yaml, _AssetsYaml):
        world.yaml = _AssetsYaml(world.yaml)


@contextlib.contextmanager
def light() -> Iterator[None]:
    """World builds inside this block skip the render-only skybox (this thread only)."""
    before = getattr(_state, "light", False)
    _state.light = True
    try:
        yield
    finally:
        _state.light = before
