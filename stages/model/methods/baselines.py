"""Registers the baselines (imported by ``methods.build_model`` when it first needs a method).

MK-Planes, MK-Planes*, CoNeRF-style and K-Planes (time) register themselves
by name on import; importing this module makes all four trainable with
``livescene train --method NAME``.
"""

from __future__ import annotations

from . import conerf, k_planes, mk_planes

BASELINES = ("mk-planes", "mk-planes-star", "conerf", "k-planes")
"""Registered baseline names (LiveScene itself is ``livescene``)."""

__all__ = ["BASELINES", "conerf", "k_planes", "mk_planes"]
