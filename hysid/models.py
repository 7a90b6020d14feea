"""The model presets as objects that compose with the effect library.

    import hysid
    model = hysid.models.thesis + hysid.effects.coulomb_friction
    model = model.fix(meq=0.04).with_bounds({"w0": (50.0, 400.0)})
    hysid.fit(loops, model)

``baseline``: the 1-DOF oscillator of Eq. 4.4 / 4.6 (``xi0``, ``w0``, ``meq``);
``thesis``: the final model of Eq. 4.8-4.10 (``xi0``, ``S_xi``, ``w0``, ``S_w``,
``meq``); ``mr_damper``: the oscillator and a Bouc-Wen spring with its exponent
free (``bw_k``, ``bw_zy``, ``bw_r``, ``bw_n``), a magnetorheological damper.
Models never change in place, so these presets stay as they are.
"""

from hysid_model.model import Model, build_model

baseline: Model = build_model("baseline")
thesis: Model = build_model("thesis")
mr_damper: Model = build_model("mr_damper")

__all__ = ["Model", "baseline", "build_model", "mr_damper", "thesis"]
