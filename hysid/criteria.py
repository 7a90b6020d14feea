"""The thresholds by which a diagnosis accepts an effect (judgment calls, stated in every report; the choice of the
displacement reading, :mod:`hysid.motion`, takes the same BIC margin)."""

SIGNIFICANCE = 1e-3
"""Family-wise level of the score tests in one round."""
BIC_MARGIN = 10.0
"""BIC difference counted as decisive (Kass and Raftery's 'very strong'), for acceptance and for confusability."""
MIN_Z = 3.0
"""|strength| / standard error an accepted effect needs."""
MIN_SHARE = 0.2
"""Fraction of the excess chi^2 (chi^2 - dof) an accepted effect must remove."""
PARALLEL = 0.9
"""|cos| between two effects' projected signatures above which they are nearly one shape: refitted together in a
round (:mod:`hysid.diagnosis.selection`), alternatives rather than partners for rule 9 (:func:`hysid.diagnosis.acceptance.own_shape`)."""
LINEAR_LOOPS = 1.25
"""A linear fit per loop this close to the noise floor (whitened RMS): the loops themselves are linear, so what a
model misses is how its linear stiffness, damping or mass change from loop to loop (the report says so)."""
