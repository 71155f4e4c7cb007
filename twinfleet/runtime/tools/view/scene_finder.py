"""How a viewer that finds a fleet only over Zenoh learns the fleet's scene and latched topics.

`twinfleet view` and `twinfleet foxglove` join a fleet by its router (``--connect``
or the fleet registry's endpoint); they have no scenario at hand. The fleet's
launcher, and `twinfleet play` for a recording, serve the fleet's description on
``twinfleet/<fleet>/@fleet`` (`runtime.host.keys.fleet_key`): the import
name of the scenario's scene and the topics its nodes declare transient-local.

A `SceneFinder` asks for it when the fleet's first sample arrives: by then the
launcher serves it (it does before any node starts), and a viewer started
before the fleet asks nothing in vain. The question runs in a worker thread;
the answer adds the latched topics to the tap (a map published before the
viewer joined still comes, from history) and hands the scene, or None for a
fleet that names none or whose scene cannot be imported here, to `found`.
The viewers keep what arrives meanwhile and draw it then. A fleet that does
not answer (not launched by twinfleet) is asked again, at most every
`ASK_AGAIN_S`, while its samples keep coming. The scene is learned once: a
fleet launched again on the same endpoint is drawn with the first run's scene.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO, final

from twinfleet.runtime.contract.scene import Scene
from twinfleet.runtime.host.keys import ANY, topic_in_fleet
from twinfleet.runtime.scenario.scenes import SceneError, load_scene
from twinfleet.runtime.tools.monitor.graph import fleet_infos

ASK_TIMEOUT_S = 1.0
ASK_AGAIN_S = 2.0


@final
class SceneFinder:
    """Learns the scene of the fleet a `FleetTap` hears (module docstring).

    Args:
        tap: the tap whose session asks, and which gets the latched topics.
        found: called on the loop, once, with the scene or None.
        out: where a scene that cannot be loaded is reported.
    """

    def __init__(self, tap: Any, found: Callable[[Scene | None], None], *,
                 out: TextIO = sys.stderr) -> None:
        self.tap, self.found, self.out = tap, found, out
        self.done = False
        self._asking: asyncio.Task[None] | None = None
        self._asked_at = -ASK_AGAIN_S

    def seen(self, key: str) -> None:
        """Note a sample of `key` (call on the loop, before handing it on)."""
        where = topic_in_fleet(ANY, key)
        if self.done or where is None or (self._asking is not None and not self._asking.done()):
            return
        if time.monotonic() - self._asked_at < ASK_AGAIN_S:
            return
        self._asked_at = time.monotonic()
        self._asking = asyncio.ensure_future(self._ask(where.fleet))

    async def _ask(self, fleet: str) -> None:
        session = self.tap.session
        info: Any = None
        with contextlib.suppress(Exception):  # a session closed meanwhile: ask again later
            info = (await asyncio.to_thread(fleet_infos, session, fleet, ASK_TIMEOUT_S)).get(fleet)
        if not isinstance(info, dict) or self.done:
            return
        self.done = True
        self.tap.add_latched([t for t in info.get("latched") or () if isinstance(t, str)])
        self.found(self._load(info.get("scene"), fleet))

    def _load(self, name: Any, fleet: str) -> Scene | None:
        if not isinstance(name, str):
            return None
        try:
            return load_scene(name)
        except SceneError as exc:
            print(f"warning: fleet {fleet} names scene {name}, which cannot be loaded here "
                  f"({exc}); only its topics are shown", file=self.out, flush=True)
            return None

    async def close(self) -> None:
        """Wait for a question under way (it ends within its timeout)."""
        if self._asking is not None:
            await asyncio.gather(self._asking, return_exceptions=True)
