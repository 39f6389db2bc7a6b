"""Numbers shared by the calculator (``calculator.py``) and its compiled kernels (``kernel.py`` and the
optimisers' kernels). A plain module without numba, so that the calculator imports it at no cost; the kernel
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

# The air brake's cycle on a long descent (``kernel.run_plans``; docs/model.md).
CYCLE_MARGIN = 1.25
"""Safety factor of the cycle's rules: the release speed lies this many times the recharge time's speed gain
(full electric brake, the grade of the application) below the apply speed, and the apply speed this many
times the build-up's overshoot below the limit."""
APPLY_MIN_KMH = 1.0
"""The apply speed lies at least this far below the limit (or the cruise speed) it keeps [km/h]."""
RELEASE_FLOOR = 0.5
"""The release speed is at least this share of the apply speed (a deeper cycle is not driven: where the
recharge needs more, the next application comes too early and the plan is refused)."""
ELECTRIC_CURVE_SHARE = 0.9
"""The electric brake's own braking curves (what a train whose air brake recharges may follow) are built on
this share of its force: following one keeps a reserve, so that the calculator, which checks the force at
the train's mid-cell speed rather than the curve's, never finds it short by a rounding."""
LOOKAHEAD_MARGIN_KMH = 0.5
"""A release's look-ahead (``kernel.release_safe``) finds it unsafe where the train would come within this of an
apply speed [km/h] before the recharge is over: its one step per cell may misjudge the speed by a few hundredths
of a km/h over a kilometre, and a release judged safe by a hair was found applying again a few seconds early."""
ARRIVE_AFTER_S = 0.5
"""A train whose air brake recharges, slowed so as to reach the next braking curve that needs it no sooner
than the recharge is over, aims to reach it this long after [s] (not on the very instant)."""
AIR_OFF, AIR_ON, AIR_APPLIED, AIR_RELEASED = 0, 1, 2, 3
"""The air brake's state in a cell of a profile: released, applied, applied in this cell (an application
begins here), released at this cell's start (a release)."""
