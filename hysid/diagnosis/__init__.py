"""``hysid diagnose``: which physical effect is the model missing?

:func:`hysid.diagnosis.selection.diagnose` reduces the loops to harmonics,
fits the start model, scores the effect library against the residual, and adds
effects one at a time while the data demand them; the :class:`Diagnosis` it
returns reports itself (:mod:`hysid.report.diagnosis` writes the Markdown/PNG
report).
"""
