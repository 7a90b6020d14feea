"""The mutants of ``bench/mutation.py`` examined by hand: those no test can tell from the original (``EQUIVALENT``,
reported apart and left out of the score) and the survivors mutmut cannot have killed (``UNTESTABLE``, counted as
survivors all the same)."""

AT_EQUALITY = (
    "differs from the original only where a statistic of the data (a sum of squared whitened residuals, a BIC "
    "difference) equals its threshold exactly, which no fit reaches: equivalent in practice"
)
EQUIVALENT: dict[str, str] = {
    "hysid.diagnosis.acceptance.x_created_order__mutmut_9": "reshape(n_loops, -2): numpy 2 reads any negative size as the one unknown dimension, as -1",
    "hysid.diagnosis.acceptance.x_created_order__mutmut_36": AT_EQUALITY,
    "hysid.diagnosis.acceptance.x_created_order__mutmut_37": AT_EQUALITY,
    "hysid.diagnosis.acceptance.x_created_order__mutmut_39": AT_EQUALITY,
    "hysid.diagnosis.acceptance.x_judge__mutmut_4": AT_EQUALITY,
    "hysid.diagnosis.acceptance.x_judge__mutmut_32": AT_EQUALITY,
    "hysid.diagnosis.acceptance.x_judge__mutmut_29": (
        "excess >= 0: rule 5 is reached only past rule 1, whose BIC fall of BIC_MARGIN lowered the chi^2 by "
        "more than 10; with no excess, 'removes less than 0' never holds either way"
    ),
    "hysid.diagnosis.acceptance.x_judge__mutmut_30": (
        "excess > 1: past rule 1 the chi^2 fell by more than 10, above MIN_SHARE times any excess up to 1, "
        "so rule 5 cannot fire for an excess in (0, 1] either way"
    ),
    "hysid_model.plausibility.x__outliers__mutmut_9": "np.finfo(None) is float64's, as np.finfo(float), in numpy 2.4 (with a DeprecationWarning)",
    "hysid_model.plausibility.x__outliers__mutmut_22": "dtype of the empty result: no outlier is only counted and set-differenced, never used to index",
    "hysid_model.plausibility.x__outliers__mutmut_24": "dtype of the empty result: no outlier is only counted and set-differenced, never used to index",
    "hysid_model.plausibility.x_amplitude_drift__mutmut_41": "the divisor put in where the level is 0, whose quotient np.where then drops",
    "hysid_model.plausibility.x_warn_loops__mutmut_107": "x0.size >= 1: a single loop has no other to be far from (_outliers of one value is empty)",
    "hysid_model.plausibility.x_warn_loops__mutmut_134": "the slips' complement is never empty (the largest group is not a slip), so 'the others' is never used",
    "hysid_model.plausibility.x_warn_loops__mutmut_139": "the text of the branch that is never taken (see x_warn_loops__mutmut_134)",
    "hysid_model.plausibility.x_warn_loops__mutmut_140": "the text of the branch that is never taken (see x_warn_loops__mutmut_134)",
    "hysid_model.uncertainty.x_scaled_inverse__mutmut_14": (
        "the scale put in for a zero diagonal: an information matrix's row and column there are "
        "zero, so any nonzero scale leaves zeros and the pseudo-inverse is 0 there"
    ),
    "hysid_model.uncertainty.x_scaled_inverse__mutmut_17": "hermitian=None: the pseudo-inverse by SVD instead of eigh, the same matrix to rounding",
    "hysid_model.uncertainty.x_scaled_inverse__mutmut_19": "hermitian left out: the pseudo-inverse by SVD instead of eigh, the same matrix to rounding",
    "hysid_model.uncertainty.x_scaled_inverse__mutmut_25": "hermitian=False: the pseudo-inverse by SVD instead of eigh, the same matrix to rounding",
    "hysid_model.readers.channels.x_choose__mutmut_13": "rsplit('/') without a maximum: its last part is rsplit('/', 1)'s",
    "hysid_model.readers.channels.x_choose__mutmut_16": "rsplit('/', 2): its last part is rsplit('/', 1)'s",
    "island.sealing.xǁReplayGuardǁcheck__mutmut_44": (
        "a shift of the window or more leaves nothing of the mask but the new number's bit: the shortcut 'else 1' gives the same"
    ),
    "island.sealing.xǁReplayGuardǁcheck__mutmut_51": (
        "a mask of window + 1 bits: the extra bit is an age of exactly the window, which 'age >= window' refuses before reading it"
    ),
    "island.sealing.xǁReplayGuardǁcheck__mutmut_53": "shift <= window: at shift == window both branches leave only the new number's bit",
    "island.sealing.xǁReplayGuardǁcheck__mutmut_75": "popitem(last=None): None is false, as last=False (the oldest run goes first)",
    "island.secret.x_read_owner_only__mutmut_19": "encoding 'ASCII': the same codec as 'ascii'",
    "island.secret.x_write_owner_only__mutmut_26": "encoding 'ASCII': the same codec as 'ascii'",
    "island.secret.x_write_owner_only__mutmut_5": "token_hex(None): a longer random suffix of the partial file's name, as unique",
    "island.secret.x_write_owner_only__mutmut_6": "token_hex(5): a longer random suffix of the partial file's name, as unique",
    "island.secret.x_write_owner_only__mutmut_33": "missing_ok=None: the partial file exists whenever a write fails after opening it",
    "island.secret.x_write_owner_only__mutmut_34": "missing_ok=False: the partial file exists whenever a write fails after opening it",
    "coordinator.members.xǁMembershipǁsettle__mutmut_7": (
        "'> LEAVE_GRACE_S': differs only where a token has been gone exactly that long to the clock's last digit"
    ),
    "coordinator.members.xǁMembershipǁheard__mutmut_45": "resumed = None: None is false as False, and resumed is only read as a truth value (if member.resumed)",
    "coordinator.members.xǁMembershipǁsettle__mutmut_18": "'> stale_s': differs only where a run has been silent exactly that long to the clock's last digit",
    "hysid.identifiability.x_unseen__mutmut_24": "'<=' for '<': differs only for an eigenvalue exactly RANK_TOL times the largest, to the last digit",
    "hysid.identifiability.x_unseen__mutmut_30": (
        "max(values.max(), 1.0): the Gram matrix of unit columns has trace D with ones on its diagonal, so its largest "
        "eigenvalue is at least 1 unless every column is zero, where any positive threshold finds every direction unseen"
    ),
    "hysid.identifiability.x_side_width__mutmut_46": "'<=' for '<': differs only for a bracket whose ends are exactly 1.02 apart, to the last digit",
    "hysid.identifiability.x_side_width__mutmut_74": "'<=' for '<': differs only for a rise whose square root is exactly 0.05 from 1, to the last digit",
    "hysid.identifiability.x_assess__mutmut_177": "'named or True': with nothing named the comprehension keeps no direction, the same (D, 0) as the else branch",
    "hysid.identifiability.x_assess__mutmut_184": "'>=' for '>': differs only for a direction's component exactly PARTICIPATION, to the last digit",
    "hysid.identifiability.x_partners__mutmut_20": "the scale put in for a column of norm 0: that column is all zeros, and stays so divided by anything",
    "hysid.identifiability.x_partners__mutmut_26": "lstsq without rcond: numpy 2's default is rcond=None",
    "hysid.identifiability.x_partners__mutmut_32": AT_EQUALITY,
    "hysid.identifiability.x_partners__mutmut_36": "the flags of an empty coefficient vector (one parameter): nothing iterates over them",
    "hysid.identifiability.x_partners__mutmut_38": "the flags of an empty coefficient vector (one parameter): nothing iterates over them",
    "hysid.identifiability.x_partners__mutmut_39": "the flags of an empty coefficient vector (one parameter): nothing iterates over them",
    "hysid.identifiability.x_assess__mutmut_6": "theta's dtype left to numpy: every caller hands a fit's optimum, already floats",
    "hysid.identifiability.x_assess__mutmut_8": "theta's dtype left to numpy: every caller hands a fit's optimum, already floats",
    "hysid.identifiability.x_assess__mutmut_10": "reshape(-2): numpy 2 reads any negative size as the one unknown dimension, as -1",
    "hysid.identifiability.x_assess__mutmut_25": "cov's dtype left to numpy: every caller hands a float covariance",
    "hysid.identifiability.x_assess__mutmut_27": "cov's dtype left to numpy: every caller hands a float covariance",
    "hysid.identifiability.x_assess__mutmut_43": AT_EQUALITY,
    "hysid.identifiability.x_assess__mutmut_45": "the flags where no direction is unseen: zeros of another dtype are as false",
    "hysid.identifiability.x_assess__mutmut_47": "the flags where no direction is unseen: zeros of another dtype are as false",
    "hysid.identifiability.x_assess__mutmut_49": "errstate without divide='ignore': a division by zero needs a covariance entry beside a zero variance, which a covariance (positive semidefinite) cannot have; 0/0 is 'invalid', still ignored",
    "hysid.identifiability.x_assess__mutmut_51": "errstate without divide='ignore': a division by zero needs a covariance entry beside a zero variance, which a covariance (positive semidefinite) cannot have; 0/0 is 'invalid', still ignored",
    "hysid.identifiability.x_assess__mutmut_64": "the diagonal filled with NaN instead of 0: the next line counts a non-finite correlation as 0",
    "hysid.identifiability.x_assess__mutmut_70": "max without initial: it only matters for a reduction over nothing, and a (D, D) matrix with D >= 1 has none",
    "hysid.identifiability.x_assess__mutmut_72": "max without initial: it only matters for a reduction over nothing, and a (D, D) matrix with D >= 1 has none",
    "hysid.identifiability.x_assess__mutmut_83": AT_EQUALITY,
    "hysid_model.model.xǁModelǁ_on_bounds__mutmut_4": "theta's dtype left to numpy: every caller hands floats",
    "hysid_model.model.xǁModelǁ_on_bounds__mutmut_6": "theta's dtype left to numpy: every caller hands floats",
    "hysid_model.model.xǁModelǁ_on_bounds__mutmut_8": "reshape(-2): numpy 2 reads any negative size as the one unknown dimension, as -1",
    "hysid_model.model.xǁModelǁ_on_bounds__mutmut_23": "'<' for '<=': differs only for a value as far from both bounds, on a bound: a range of width 0",
    "hysid.motion.x_linear_start__mutmut_11": (
        "a strict subset: every model holds xi0 and w0 besides the slopes, so {S_xi, S_w} <= its parameters exactly where {S_xi, S_w} < them"
    ),
}
"""mutmut's mutant name -> why no test can tell it from the original (examined by hand; mutmut numbers a function's
mutants in a fixed order, so a name stays right while its function is unchanged)."""
UNTESTABLE = {
    "stacklevel": (
        "a warning's stacklevel: mutmut's trampoline adds a frame between the caller and the function, so no "
        "test of where a warning points can pass under it (the original's stacklevel is right)"
    ),
}
"""Why a survivor that mutmut cannot have killed survives (counted as survivors all the same)."""
