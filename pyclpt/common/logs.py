"""The ``pyclpt`` logger: where warnings go, and a way to collect them.

Loaders report what a scene uses that pyclpt ignores or approximates as warnings on the
``pyclpt`` logger; :func:`captured_warnings` collects them for a report or a test.
"""
from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

LOGGER_NAME = "pyclpt"
#: Messages for a user waiting at the command line (pyclpt.device.program's compile message), at INFO:
#: the command line shows them unless --quiet; a library user sees them only by enabling this logger.
NOTICE_LOGGER = "pyclpt.notice"


class _Collector(logging.Handler):
    def __init__(self, messages: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.messages = messages

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def captured_warnings() -> Iterator[list[str]]:
    """Collect the messages of the warnings logged under ``pyclpt`` inside the ``with`` block
    (they still reach the other handlers)."""
    messages: list[str] = []
    handler = _Collector(messages)
    logger = logging.getLogger(LOGGER_NAME)
    logger.addHandler(handler)
    try:
        yield messages
    finally:
        logger.removeHandler(handler)
