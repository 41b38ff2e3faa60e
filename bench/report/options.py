"""The option types of ``pyclpt bench`` (and of ``--versus mitsuba``, bench/denoise_eval.py): argparse
types that say what they expected."""
from __future__ import annotations

import argparse


def positive(text: str) -> int:
    """An argparse type: an integer of at least 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def size_type(keyword: str, minimum: int = 1):
    """An argparse type: ``WIDTHxHEIGHT`` (each at least ``minimum``), or ``keyword`` as it is."""

    def parse(text: str) -> str:
        if text == keyword:
            return text
        try:
            w, h = (int(x) for x in text.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT or {keyword!r}, got {text!r}") from None
        if w < minimum or h < minimum:
            raise argparse.ArgumentTypeError(f"the size must be at least {minimum}x{minimum}, got {text!r}")
        return f"{w}x{h}"

    return parse


#: ``--resolution``: WIDTHxHEIGHT, or ``scene`` (the scene's own)
resolution = size_type("scene")
