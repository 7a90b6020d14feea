"""Random numbers of the islands: a seeded generator whose state survives msgpack, and Eq. 3.2.

The optimizers draw from one ``numpy.random.Generator`` on PCG64. Its state
holds two 128-bit integers, which msgpack cannot carry, so :func:`rng_state`
writes them as decimal strings and :func:`rng_from_state` reads them back; a
restored generator continues the stream bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError


def new_rng(seed: int) -> np.random.Generator:
    """A PCG64 generator for ``seed``."""
    return np.random.Generator(np.random.PCG64(seed))


def rng_state(rng: np.random.Generator) -> dict[str, Any]:
    """The generator state as msgpack-safe plain data (128-bit integers as strings)."""
    state = rng.bit_generator.state
    if state["bit_generator"] != "PCG64":
        raise ValueError(f"only PCG64 generators are checkpointed, got {state['bit_generator']}")
    return {
        "bit_generator": "PCG64",
        "state": str(state["state"]["state"]),
        "inc": str(state["state"]["inc"]),
        "has_uint32": int(state["has_uint32"]),
        "uinteger": int(state["uinteger"]),
    }


def rng_from_state(data: dict[str, Any]) -> np.random.Generator:
    """Rebuild the generator saved by :func:`rng_state`."""
    if data.get("bit_generator") != "PCG64":
        raise HysidInputError(f"checkpoint: random generator {data.get('bit_generator')!r} is not PCG64")
    try:
        bit_generator = np.random.PCG64()
        bit_generator.state = {
            "bit_generator": "PCG64",
            "state": {"state": int(data["state"]), "inc": int(data["inc"])},
            "has_uint32": int(data["has_uint32"]),
            "uinteger": int(data["uinteger"]),
        }
    except (KeyError, TypeError, ValueError) as exc:
        raise HysidInputError(f"checkpoint: random generator state is malformed ({exc})") from exc
    return np.random.Generator(bit_generator)


def uniform_population(rng: np.random.Generator, bounds: np.ndarray, n: int) -> np.ndarray:
    """``n`` chromosomes uniform in the bounds, p_ij = (ub_j - lb_j) rand + lb_j (Eq. 3.2, ``genipop``)."""
    lower, upper = bounds[:, 0], bounds[:, 1]
    return lower + (upper - lower) * rng.random((n, bounds.shape[0]))
