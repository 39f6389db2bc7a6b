"""Numbers shared by the calculator's numpy loop (``calculator.py``) and its compiled kernel
(``kernel.py``). A plain module without numba, so that the calculator imports it at no cost; the kernel
reads them as compile-time constants, so this file is part of the compiled module's hash
(``locoplan.sim.native``): changing a number here rebuilds the kernels."""

from ..physics.units import kinetic_e

E_FLOOR = 1e-6
"""e = v^2/2 [m^2/s^2] a stalled plan is held at: keeps its arithmetic finite once it is marked infeasible."""
CRAWL_KMH = 15.0
"""Below this speed a cell in which the train slows (no braking) is integrated again in sub-steps of at
most ``CRAWL_STEP_M``: one step over a 50 m cell misjudged whether a weak train crawling over a crest
stalls (a plan passed on 50 m cells and stalled on 25 m ones); the sub-steps settle it."""
CRAWL_STEP_M = 5.0
E_CRAWL = kinetic_e(CRAWL_KMH)
"""``CRAWL_KMH`` as e = v^2/2 [m^2/s^2]."""
