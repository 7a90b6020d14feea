"""``hysid diagnose``: which physical effect is the model missing?

:func:`coordinator.diagnose.selection.diagnose` reduces the loops to harmonics,
fits the start model, scores the effect library against the residual, and adds
effects one at a time while the data demand them; :mod:`.report` writes the
Markdown/PNG report.
"""
