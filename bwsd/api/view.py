"""What the API reads of the controller without ever racing its run loop or blocking it.

A copy of the skeleton costs the size of the preform: it is taken in a worker thread, never
on the event loop. The instruction events carry the skeleton's change, built by the run loop
in a worker thread as well (``bwsd.export.skeleton_json.delta_to_dict``).
"""

from __future__ import annotations

import asyncio

from bwsd.controller.facade import Controller
from bwsd.twin import SkeletonData, Twin


class SkeletonView:
    """The skeleton as the API serves it: copied from the twin in a worker thread.

    The twin's readers take its lock, so a copy is consistent even while the run loop
    predicts; the copy is kept until the twin has changed.
    """

    def __init__(self, controller: Controller) -> None:
        self._ctl = controller
        self._twin: Twin | None = None  # the twin the copy was taken of (held: never reused)
        self._done = -1
        self._copy: SkeletonData | None = None

    async def current(self) -> SkeletonData | None:
        """The skeleton after the last instruction committed; None when no program is loaded."""
        twin = self._ctl.twin
        if twin is None:
            return None
        if self._twin is not twin or self._done != twin.done or self._copy is None:
            copy = await asyncio.to_thread(twin.skeleton)
            self._twin, self._done, self._copy = twin, copy.instructions, copy
            return copy
        return self._copy
