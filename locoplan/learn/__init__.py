"""The pattern-curve patent: double-layer pattern curves learned from drivers' logs, and the advice they give.

- ``drivers``: a simulator of human drivers that makes driver logs (labelled synthetic); the format
  (one CSV per run + a YAML manifest) is ``model/logs.py``, read by ``io/logs.py``, written by
  ``reporting/logs.py``.
- ``segments``: the route split by equivalent gradient into the five section types (claims 4-6).
- ``patterns``: good drivers (claim 3), the upper layer (eq. I) and the lower layer (eq. II); a
  patterns.json is read by ``io/patterns.py``, checked and built by ``Patterns.from_dict``.
- ``advise``: time shares and speed curve for a new run, turned into a condition sequence (claim 2)
  and checked by the traction calculator.
- ``strategies``: ``drivers`` and ``advice`` as strategies of ``compare`` (listed in strategy/registry.py).
"""
