"""Seed 004: double-layer pattern curves learned from drivers' logs, and the advice they give.

- ``logs``: the driver-log format (one CSV per run + a YAML manifest), loader and writer.
- ``drivers``: a simulator of human drivers that writes such logs (labelled synthetic).
- ``segments``: the route split by equivalent gradient into the five section types (claims 4-6).
- ``patterns``: good drivers (claim 3), the upper layer (eq. I) and the lower layer (eq. II).
- ``advise``: time shares and speed curve for a new run, turned into a condition sequence (claim 2)
  and checked by the traction calculator.
- ``strategies``: ``drivers`` and ``advice`` as strategies of ``compare`` (listed in strategy/registry.py).
"""
