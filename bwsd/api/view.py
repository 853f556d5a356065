"""What the API reads of the controller without ever racing its run loop or blocking it.

A copy of the skeleton costs the size of the preform: it is taken in a worker thread, never
on the event loop. The instruction events carry the skeleton's change, built by the run loop
in a worker thread as well (``bwsd.export.skeleton_json.delta_to_dict``). The relaxed
preform takes seconds: a worker process makes it (RelaxedView).
"""

from __future__ import annotations

import asyncio
import json
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

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


def _relaxed_json(sk: SkeletonData, warp_tension: float, weft_tension: float) -> bytes:
    """In the worker process: relax ``sk`` and give the document of docs/relax.md as JSON."""
    from bwsd.relax import Options, relax
    from bwsd.relax.document import relaxed_to_dict

    relaxed = relax(sk, Options(warp_tension=warp_tension, weft_tension=weft_tension))
    return json.dumps(relaxed_to_dict(relaxed), allow_nan=False).encode()


class RelaxedView:
    """The relaxed preform of the committed skeleton (docs/relax.md), off the control path.

    Relaxing takes seconds: it runs in a worker process of its own (one, started on first
    use with ``spawn``), never on the event loop nor in the run loop's threads, so no
    instruction waits for it. The answer is cached per twin and ``done`` index; requests for
    the index being relaxed share the one computation. The twin's contacts still decide
    every refusal: nothing here reaches the controller.
    """

    def __init__(
        self, skeleton: SkeletonView, warp_tension: float = 1.0, weft_tension: float = 1.0
    ) -> None:
        self._skeleton = skeleton
        self._tensions = (warp_tension, weft_tension)
        self._pool: ProcessPoolExecutor | None = None
        self._key: tuple[int, int] | None = None  # (id of the twin's copy, done)
        self._answer: asyncio.Future[bytes] | None = None
        self.computed = 0  # relaxations run (the cache's misses)

    async def current(self) -> bytes | None:
        """The relaxed document of the skeleton after the last committed instruction, as
        JSON; None when no program is loaded."""
        sk = await self._skeleton.current()
        if sk is None:
            return None
        key = (id(sk), sk.instructions)
        if self._key != key or self._answer is None or self._answer.cancelled():
            if self._pool is None:
                self._pool = ProcessPoolExecutor(1, mp_context=get_context("spawn"))
            loop = asyncio.get_running_loop()
            self._key, self.computed = key, self.computed + 1
            self._answer = asyncio.ensure_future(
                loop.run_in_executor(self._pool, _relaxed_json, sk, *self._tensions)
            )
        answer = self._answer
        try:
            return await asyncio.shield(answer)
        except Exception:
            if self._answer is answer:
                self._key = self._answer = None  # a failed relaxation is not kept
            raise

    def close(self) -> None:
        """Stop the worker process (a relaxation under way is abandoned)."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
