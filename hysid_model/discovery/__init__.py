"""Discovery of a force law the effect library lacks, from what the best library model leaves.

* :mod:`.features`: the candidate library, families of force shapes of the loops' state (displacement and
  velocity, their signs and magnitudes, powers, products, one-sided and dead-zone features, saturating
  velocity laws), each a numpy expression in ``x`` (m) and ``v`` (m/s) with shape parameters on a grid
  scaled by the loops' amplitudes and velocities;
* :mod:`.memory`: the family with memory, the Bouc-Wen internal variable of each loop's displacement history
  on its steady orbit (compiled), on a grid of yield displacements and knee exponents;
* :mod:`.frols`: sparse selection among their columns by forward regression with orthogonal least squares
  and the error-reduction ratio (FROLS), and the refinement of the shape parameters by nonlinear least squares;
* :mod:`.proposal`: a selected law as a term of the user's kind (:func:`hysid_model.user_terms.term`), its
  formula with the fitted values in place (for a law with memory, the rate of its force), and the Python module
  that defines it for reuse.

The diagnosis (:mod:`hysid.diagnosis.discovery`) runs it where no library effect brings the residual to the
noise, and judges the proposal by the rules that accept a library effect.
"""
