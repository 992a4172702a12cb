"""The ``with`` protocol of a resource that closes: one definition for the capture
writer, the virtual port and the daemon process."""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType
from typing import Self


class Closing(ABC):
    """A resource for a ``with`` block: entering returns it, leaving calls :meth:`close`
    (whatever the exit, an exception included, which then propagates)."""

    @abstractmethod
    def close(self) -> None:
        """Release the resource (idempotent)."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
