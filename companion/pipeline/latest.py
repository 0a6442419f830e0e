"""A one-slot asyncio channel that keeps the newest item: a stale frame is worth less
than a dropped one."""

from __future__ import annotations

import asyncio
from typing import Generic, TypeVar

T = TypeVar("T")


class LatestSlot(Generic[T]):
    """``put`` never blocks and replaces an item nobody took yet (counted in ``dropped``);
    ``get`` waits for the next item.  Only for use on one event loop."""

    def __init__(self) -> None:
        self._item: T | None = None
        self._has_item = False
        self._event = asyncio.Event()
        self._closed = False
        self.dropped = 0
        self.put_count = 0

    def put(self, item: T) -> None:
        """Offer the newest item, dropping an untaken older one."""
        if self._has_item:
            self.dropped += 1
        self._item = item
        self._has_item = True
        self.put_count += 1
        self._event.set()

    def close(self) -> None:
        """Wake the reader; ``get`` then raises :class:`SlotClosedError` once empty."""
        self._closed = True
        self._event.set()

    async def get(self) -> T:
        """The newest item; waits for one."""
        while not self._has_item:
            if self._closed:
                raise SlotClosedError
            self._event.clear()
            await self._event.wait()
        item = self._item
        self._item = None
        self._has_item = False
        return item  # type: ignore[return-value]


class SlotClosedError(Exception):
    """The producer closed the slot and nothing is left."""
